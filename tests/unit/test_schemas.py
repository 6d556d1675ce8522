"""``schemas/``: current (``pfp schemas --check``), regenerable, and only ever growing."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from pfp_service.cli import main
from pfp_service.wire import messages as m
from pfp_service.wire import schema
from pfp_service.world import translate

ROOT = Path(__file__).resolve().parents[2]
SCHEMAS = ROOT / "schemas"


def pfp(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "pfp_service", *args], capture_output=True, text=True, cwd=cwd, timeout=120
    )


@pytest.mark.proc
def test_committed_schemas_are_current() -> None:
    """The CI gate: fails when a message changed and nobody ran ``pfp schemas``."""
    r = pfp("schemas", "--check")
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "schemas: up to date"


@pytest.fixture
def copy(tmp_path: Path) -> Path:
    target = tmp_path / "schemas"
    shutil.copytree(SCHEMAS, target)
    return target


@pytest.mark.proc
@pytest.mark.parametrize(
    ("damage", "line"),
    [
        (lambda d: (d / "goal.schema.json").write_text("{}\n"), "changed goal.schema.json"),
        (lambda d: (d / "examples" / "threat.json").unlink(), "missing examples/threat.json"),
        (lambda d: (d / "old.schema.json").write_text("{}\n"), "extra old.schema.json"),
        (lambda d: (d / "index.json").write_text((d / "index.json").read_text() + " "), "changed index.json"),
    ],
)
def test_check_names_what_is_stale_and_regenerating_fixes_it(copy: Path, damage: Any, line: str) -> None:
    damage(copy)
    r = pfp("schemas", "--check", "--dir", str(copy))
    assert r.returncode == 1
    assert f"pfp schemas: {copy}: {line}" in r.stderr.splitlines()
    assert "run `pfp schemas`" in r.stderr
    assert main(["schemas", "--dir", str(copy)]) == 0
    assert main(["schemas", "--check", "--dir", str(copy)]) == 0


@pytest.mark.unit
def test_regenerating_into_an_empty_directory_writes_everything(tmp_path: Path) -> None:
    target = tmp_path / "fresh"
    assert main(["schemas", "--check", "--dir", str(target)]) == 1
    assert main(["schemas", "--dir", str(target)]) == 0
    written = sorted(p.relative_to(target).as_posix() for p in target.rglob("*") if p.is_file())
    assert written == sorted(schema.render(translate.supplied()))
    assert all((target / rel).read_text() == (SCHEMAS / rel).read_text() for rel in written)


@pytest.mark.unit
def test_render_needs_the_types_the_wire_cannot_name() -> None:
    # the wire imports no core: without translate's PlanResult there is no preview reply to publish
    with pytest.raises(ValueError, match="preview_reply"):
        schema.render({})
    extra = {**translate.supplied(), "goal": schema.Supplied(m.Goal, ())}
    with pytest.raises(ValueError, match="goal"):
        schema.render(extra)


@pytest.mark.proc
def test_a_file_as_dir_is_one_line_and_exit_2(tmp_path: Path) -> None:
    f = tmp_path / "f"
    f.write_text("x")
    r = pfp("schemas", "--dir", str(f))
    assert r.returncode == 2
    assert r.stderr == f"pfp schemas: {f}: is not a directory\n"


@pytest.mark.proc
def test_a_bad_flag_is_one_line_and_exit_2() -> None:
    r = pfp("schemas", "--chek")
    assert r.returncode == 2
    assert len(r.stderr.strip().splitlines()) == 1


def _index() -> dict[str, Any]:
    return json.loads((SCHEMAS / "index.json").read_text())


DECODE: dict[str, Callable[[bytes], Any]] = {
    "unit_state": m.decode_unit_state,
    "goal": m.decode_goal,
    "threat": m.decode_threat,
    "direction": m.decode_direction,
    "preview_request": m.decode_preview_request,
    "preview_reply": translate.decode_plan_result,
    "error_reply": m.decode_error_reply,
    "planner_status": m.decode_planner_status,
    "world_snapshot": m.decode_world_snapshot,
    "mission": m.decode_mission,
    "event": m.decode_event,
    "zone": m.decode_zone,
    "team": m.decode_team,
    "team_preview_request": lambda b: m.decode(m.TeamPreviewRequest, b),
    "team_preview": lambda b: m.decode(m.TeamPreview, b),
}


@pytest.mark.unit
def test_index_lists_every_message_once_with_schema_and_examples() -> None:
    index = _index()
    assert set(index["messages"]) == set(DECODE)
    assert index["encoding"] == "application/json"
    assert index["max_payload_bytes"] == m.MAX_PAYLOAD_BYTES
    for name, entry in index["messages"].items():
        doc = json.loads((SCHEMAS / entry["schema"]).read_text())
        assert doc["$schema"] == "https://json-schema.org/draft/2020-12/schema"
        assert doc["title"] == name
        refs = [doc["$ref"]] if "$ref" in doc else [r["$ref"] for r in doc["anyOf"]]
        assert all(r.removeprefix("#/$defs/") in doc["$defs"] for r in refs)
        assert entry["examples"], name


@pytest.mark.unit
@pytest.mark.parametrize("name", list(DECODE))
def test_every_example_decodes_and_re_encodes_identically(name: str) -> None:
    for rel in _index()["messages"][name]["examples"]:
        text = (SCHEMAS / rel).read_text()
        msg = DECODE[name](text.encode())
        assert json.loads(m.encode(msg)) == json.loads(text), rel


# The contract as first published (version 1).  Schemas only grow: every field
# here stays, and no field is ever required that was not required then.
V1: dict[str, tuple[set[str], set[str]]] = {
    "UnitState": ({"position"}, {"t", "seq", "kind", "speed_mps", "heading_deg", "mobility"}),
    "Goal": ({"position"}, {"delta", "tolerance", "step", "mobility"}),
    "GoalMobility": ({"class"}, {"max_slope_deg", "height_m", "speed_mps"}),
    "ThreatUpdate": (
        {"position", "sigma_range", "sigma_lateral"},
        {"facing_deg", "skew", "weight", "ttl_s"},
    ),
    "WhatIfThreat": (
        {"position", "sigma_range", "sigma_lateral", "id"},
        {"facing_deg", "skew", "weight", "ttl_s"},
    ),
    "PreviewRequest": (set(), {"start", "goal", "threats", "delta", "step", "tolerance", "max_iter"}),
    "Direction": (
        {"unit", "status", "vector"},
        {"seq", "heading_deg", "distance_to_goal", "threat_level", "lookahead", "reason"},
    ),
    "ErrorReply": ({"error"}, {"field"}),
    # positions to the planner may be {"lat", "lon"} (added with geo)
    "LatLon": ({"lat", "lon"}, set()),
    # the planner's origin in its status (added with acknowledged writes and origin checks)
    "Origin": ({"lat", "lon"}, {"alt"}),
    "TerrainInfo": (
        {"file", "sha256", "south", "west", "north", "east", "resolution_m", "unit"},
        {"origin_centred"},
    ),
    "PlannerStatus": (
        {"planner", "mission", "uptime_s"},
        {"version", "units", "units_stale", "threats", "msgs_in", "msgs_out", "rejected"}
        | {"latency_p50_ms", "latency_p99_ms"},
    ),
    "RejectedEvent": ({"kind", "key", "reason"}, {"planner", "t", "field"}),
    "ReplanEvent": ({"kind", "units", "reason"}, {"planner", "t"}),
    "TrappedEvent": ({"kind", "unit", "position"}, {"planner", "t", "reason"}),
    "ArrivedEvent": ({"kind", "unit", "position"}, {"planner", "t", "distance_to_goal"}),
    # added with the state-machine world
    "ThreatChange": ({"threat", "change"}, {"position"}),
    "StaleEvent": ({"kind", "unit", "position"}, {"planner", "t", "reason"}),
    "ForgottenEvent": ({"kind", "unit"}, {"planner", "t", "stale_s"}),
    "RestoredEvent": ({"kind"}, {"planner", "t", "threats", "goals", "missions", "expired"}),
    "ConflictEvent": ({"kind", "other"}, {"planner", "t", "reason"}),
    # dispersion's deadlocks (issue 33)
    "DeadlockEvent": (
        {"kind", "unit", "other", "position"},
        {"planner", "t", "held_s", "backoff_s", "reason"},
    ),
    "UnitSummary": (
        {"id"},
        {"kind", "status", "position", "goal", "last_seen_s", "distance_to_goal", "stale"},
    ),
    "ThreatSummary": ({"id", "threat"}, {"ttl_s"}),
    "WorldSnapshot": ({"planner", "mission"}, {"units", "threats", "units_total", "threats_total"}),
    # added with scale-out
    "Mission": ({"goal", "origin", "params"}, {"planner"}),
    "MissionParams": (
        {"delta", "step", "max_iter", "tolerance", "intensity", "escape", "trap_window", "progress_window"},
        {"seed"},
    ),
    # added with keep-out zones
    "ZoneUpdate": (set(), {"kind", "polygon", "circle", "ttl_s"}),
    "ZoneCircle": ({"centre", "radius_m"}, set()),
    "ZoneSummary": ({"id", "zone"}, {"ttl_s"}),
    # added with the write kinds listed by kind (issue 31)
    "WriteSummary": ({"kind", "id", "body"}, {"ttl_s"}),
    # added with teams
    "TeamSummary": ({"id", "team"}, {"notes"}),
    "TeamPreviewRequest": (set(), {"horizon_s", "dt_s", "speeds"}),
    "TeamPreview": (
        {"team"},
        {"eta_s", "members", "simulated_s", "stopped", "outsiders", "outsiders_left_out"},
    ),
    "MemberTrack": ({"unit"}, {"speed_mps", "points", "statuses", "arrived_s"}),
    "StatusChange": ({"t_s", "status"}, {"reason"}),
    "TeamUpdate": (
        set(),
        {"members", "separation_m", "lead", "follow", "standoff_m", "corridor_m", "controller", "robots"}
        | {"radio_range_m"},
    ),
    "PlanResult": (
        {"status", "reason", "steps", "length", "exposure", "peak_threat", "min_clearance"}
        | {"final_distance", "path", "compute_ms", "params"},
        {"events"},
    ),
}


def _defs() -> dict[str, Any]:
    defs: dict[str, Any] = {}
    for p in SCHEMAS.glob("*.schema.json"):
        defs.update(json.loads(p.read_text())["$defs"])
    return defs


# Fields once required that a later version lets go, each with its reason: every v1 message still
# decodes.  The skew-normal's spreads are required by that shape only (``ThreatUpdate.shape``).
RELAXED: dict[str, set[str]] = {
    "ThreatUpdate": {"sigma_range", "sigma_lateral"},
    "WhatIfThreat": {"sigma_range", "sigma_lateral"},
}


@pytest.mark.unit
@pytest.mark.parametrize("struct", list(V1))
def test_schemas_only_grow_and_new_fields_have_defaults(struct: str) -> None:
    d = _defs()[struct]
    required, optional = V1[struct]
    assert set(d.get("required", [])) == required - RELAXED.get(struct, set()), (
        "a new field must have a default"
    )
    assert required | optional <= set(d["properties"]), "a published field was removed"


@pytest.mark.unit
def test_every_published_struct_is_pinned() -> None:
    """PlanResult's inner types belong to the planning core; every other object is pinned."""
    core = set(json.loads((SCHEMAS / "preview_reply.schema.json").read_text())["$defs"]) - {"PlanResult"}
    objects = {name for name, d in _defs().items() if d.get("type") == "object"}
    assert objects - core - set(V1) == set(), "pin the new message's v1 fields in V1"

"""docker/ without a docker engine: the compose file parses, every file it names exists, every command is real.

Commands are checked twice: the argv is parsed by ``pfp``'s own parser (so a
bad flag value fails too), and every flag appears in ``pfp <command> --help``.
Files under ``/etc/pfp`` are the pfp-secrets volume: they must be among what
the compose file's own ``identities`` and ``certs`` services write, which is
checked by running the same two commands here.
"""

from __future__ import annotations

import importlib.metadata
import json
import re
import shlex
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
import zenoh

from pfp_service.cli import build_parser
from pfp_service.cli import main as pfp_main

pytestmark = pytest.mark.proc

ROOT = Path(__file__).resolve().parents[2]
DOCKER = ROOT / "docker"
COMPOSE = yaml.safe_load((DOCKER / "compose.yaml").read_text())
SERVICES: dict = COMPOSE["services"]
DOCKERFILE = (DOCKER / "Dockerfile").read_text()
SECRETS = "/etc/pfp"
PFP_IMAGE = "pfp-service:local"


def _dockerfile_json(instruction: str) -> list[str]:
    text = DOCKERFILE.replace("\\\n", " ")
    m = re.search(rf"^{instruction}\s+(.*)$", text, re.M)
    assert m, instruction
    rest = m[1]
    if instruction == "HEALTHCHECK":
        rest = rest.split("CMD", 1)[1]
    return json.loads(rest)


ENTRYPOINT = _dockerfile_json("ENTRYPOINT")


def _argv(svc: dict) -> list[str]:
    entry = svc.get("entrypoint", ENTRYPOINT)
    return [*entry, *svc.get("command", _dockerfile_json("CMD"))]


def _pfp_services() -> dict[str, dict]:
    return {n: s for n, s in SERVICES.items() if s.get("image") == PFP_IMAGE}


def _commands() -> list[tuple[str, list[str]]]:
    """Every command the deployment runs: services' argv and healthchecks."""
    out = []
    for name, svc in _pfp_services().items():
        out.append((name, _argv(svc)))
        hc = svc.get("healthcheck", {})
        if hc.get("test"):
            assert hc["test"][0] == "CMD", f"{name}: exec form, no shell in the healthcheck"
            out.append((f"{name} healthcheck", hc["test"][1:]))
    out.append(("Dockerfile HEALTHCHECK", _dockerfile_json("HEALTHCHECK")))
    out.append(("Dockerfile default", [*ENTRYPOINT, *_dockerfile_json("CMD")]))
    return out


@pytest.fixture(scope="module")
def secrets_volume(tmp_path_factory) -> Path:
    """What ``identities`` and ``certs`` write into pfp-secrets, run here with /etc/pfp -> a temp dir."""
    out = tmp_path_factory.mktemp("secrets")
    for name in ("identities", "certs"):
        argv = [a.replace(SECRETS, str(out)) for a in _argv(SERVICES[name])]
        if argv[0] == "pfp":
            # --runtime-dir stays /etc/pfp: the files must name where they are inside the containers
            args = argv[1:]
            args[args.index("--runtime-dir") + 1] = SECRETS
            assert pfp_main([*args, "--quiet"]) == 0, name
        else:
            assert argv[:2] == ["python", "docker/gen-certs.py"], name
            done = subprocess.run([sys.executable, *argv[1:]], cwd=ROOT, capture_output=True, text=True)
            assert done.returncode == 0, done.stderr
    return out


def test_compose_parses_and_has_the_deployment():
    assert {"router", "planner", "fleet", "injector", "identities", "certs"} <= set(SERVICES)
    assert COMPOSE["volumes"].keys() >= {"pfp-secrets", "pfp-state"}


def test_the_router_is_zenoh_pinned_to_the_installed_eclipse_zenoh():
    version = importlib.metadata.version("eclipse-zenoh")
    assert SERVICES["router"]["image"] == f"eclipse/zenoh:{version}"


def test_the_acl_is_mounted_read_only_and_is_exactly_what_pfp_acl_generates(secrets_volume):
    mounts = SERVICES["router"]["volumes"]
    (acl,) = [m for m in mounts if m.startswith("./")]
    src, dst, mode = acl.split(":")
    assert mode == "ro" and dst == SERVICES["router"]["command"][-1]
    assert (DOCKER / src).read_text() == (secrets_volume / "zenoh-router-mtls.json5").read_text()
    assert (DOCKER / "zenoh-router.json5").read_text() == (secrets_volume / "zenoh-router.json5").read_text()
    assert all(m.endswith(":ro") for m in mounts)


@pytest.mark.parametrize("name", ["zenoh-router.json5", "zenoh-router-mtls.json5"])
def test_the_shipped_router_configs_load_in_zenoh_and_deny_by_default(name):
    zenoh.Config.from_file(str(DOCKER / name))  # raises on a key zenoh does not know
    text = (DOCKER / name).read_text()
    conf = json.loads("\n".join(line for line in text.splitlines() if not line.startswith("//")))
    ac = conf["access_control"]
    assert ac["enabled"] is True and ac["default_permission"] == "deny"
    assert {r["permission"] for r in ac["rules"]} == {"allow"}
    assert conf["transport"]["link"]["rx"]["max_message_size"] == 512 * 1024
    assert conf["transport"]["shared_memory"]["enabled"] is False  # else same-host payloads skip the limit
    if "mtls" in name:
        assert conf["transport"]["link"]["tls"]["enable_mtls"] is True
        assert all("cert_common_names" in s and "usernames" not in s for s in ac["subjects"])
    else:
        assert conf["transport"]["auth"]["usrpwd"]["dictionary_file"] == f"{SECRETS}/credentials.txt"


def test_one_image_built_once_and_reused():
    built = [n for n, s in SERVICES.items() if "build" in s]
    assert len(built) == 1
    build = SERVICES[built[0]]["build"]
    assert (DOCKER / build["context"] / build["dockerfile"]).is_file()
    assert set(_pfp_services()) == {"identities", "certs", "planner", "fleet", "injector"}
    assert all(s["pull_policy"] == "never" for n, s in _pfp_services().items() if n not in built)


def test_health_gates_the_clients_and_everything_restarts_sensibly():
    for name in ("fleet", "injector"):
        assert SERVICES[name]["depends_on"]["planner"] == {"condition": "service_healthy"}
    assert SERVICES["planner"]["healthcheck"]["test"][1:3] == ["pfp", "health"]
    for name in ("fleet", "injector", "identities", "certs"):  # clients check nothing of their own
        assert SERVICES[name]["healthcheck"] == {"disable": True}
    for name in ("router", "planner"):
        assert SERVICES[name]["restart"] == "unless-stopped"
    assert SERVICES["fleet"]["restart"] == "on-failure"
    for name in ("identities", "certs", "injector"):  # one-shot
        assert SERVICES[name]["restart"] == "no"
    assert SERVICES["certs"]["depends_on"]["identities"]["condition"] == "service_completed_successfully"


def test_the_planner_is_a_client_of_the_router_with_a_state_volume():
    argv = _argv(SERVICES["planner"])
    assert argv[:2] == ["pfp", "serve"] and argv[argv.index("--mode") + 1] == "client"
    assert "pfp-state:/var/lib/pfp" in SERVICES["planner"]["volumes"]
    assert argv[argv.index("--state-dir") + 1].startswith("/var/lib/pfp/")
    assert "XDG_STATE_HOME=/var/lib/pfp" in DOCKERFILE
    assert "ports" not in SERVICES["planner"]  # only the router is published


def test_the_image_is_slim_and_non_root():
    assert re.search(r"^FROM python:3\.\d+-slim$", DOCKERFILE, re.M)
    users = re.findall(r"^USER (\S+)$", DOCKERFILE, re.M)
    assert users and users[-1] not in ("root", "0")
    for src in re.findall(r"^COPY (.+) \./", DOCKERFILE, re.M):
        for path in src.split():
            assert (ROOT / path).exists(), path


@pytest.mark.parametrize("where, argv", _commands(), ids=lambda v: v if isinstance(v, str) else "")
def test_every_command_is_a_real_pfp_subcommand_with_real_flags(where, argv):
    if argv[0] != "pfp":
        assert argv[:2] == ["python", "docker/gen-certs.py"], where
        help_text = subprocess.run(
            [sys.executable, str(ROOT / argv[1]), "--help"], capture_output=True, text=True, check=True
        ).stdout
        flags = argv[2:]
    else:
        try:
            build_parser().parse_args(argv[1:])
        except SystemExit as exc:
            pytest.fail(f"{where}: pfp rejects {shlex.join(argv)} (exit {exc.code})")
        help_text = subprocess.run(
            [sys.executable, "-m", "pfp_service", argv[1], "--help"],
            capture_output=True,
            text=True,
            cwd=ROOT,
            check=True,
        ).stdout
        flags = argv[2:]
    for flag in (a for a in flags if a.startswith("--")):
        assert re.search(rf"(^|[\s\[,]){re.escape(flag)}\b", help_text), f"{where}: {flag} not in --help"


def test_every_file_the_deployment_names_exists(secrets_volume):
    """Repository files (relative to /app in the image) and pfp-secrets files (written by the one-shots)."""
    texts = [json.dumps(SERVICES), (DOCKER / "zenoh-router-mtls.json5").read_text()]
    named = set()
    for text in texts:
        named |= set(re.findall(r"(?:examples|docker)/[\w./-]+\.(?:ya?ml|py|json5)", text))
        secret = set(re.findall(rf"{SECRETS}/[\w./-]+\.(?:pem|json5|txt)", text))
        for path in secret:
            assert (secrets_volume / path[len(SECRETS) + 1 :]).is_file(), path
    for path in named:
        assert (ROOT / path).is_file(), path
    assert "COPY examples ./examples" in DOCKERFILE and "COPY docker/gen-certs.py" in DOCKERFILE
    for name, svc in SERVICES.items():
        for mount in svc.get("volumes", []):
            src = mount.split(":")[0]
            if src.startswith("."):
                assert (DOCKER / src).is_file(), f"{name}: {src}"
            else:
                assert src in COMPOSE["volumes"], f"{name}: {src}"


def test_the_compose_endpoints_carry_each_services_own_certificate(secrets_volume):
    endpoints = dict(
        line.split(" ", 1) for line in (secrets_volume / "endpoints.txt").read_text().splitlines() if line
    )
    planner_health = SERVICES["planner"]["healthcheck"]["test"]
    assert planner_health[-1] == endpoints["planner"]
    for name in ("fleet", "injector"):
        argv = _argv(SERVICES[name])
        assert argv[argv.index("--connect") + 1] == endpoints[name], name
    client = json.loads(
        "\n".join(
            line
            for line in (secrets_volume / "clients" / "planner-tls.json5").read_text().splitlines()
            if not line.startswith("//")
        )
    )
    assert client["connect"]["endpoints"] == ["tls/router:7447"]
    assert f"{SECRETS}/clients/planner-tls.json5" in _argv(SERVICES["planner"])


@pytest.mark.alone  # its inject plays expectations on a sped-up clock (x10): see tests/conftest.py's PLACEMENT
def test_the_compose_deployment_runs_as_processes(tmp_path):
    """Compose's own commands, run here: /etc/pfp is a temp dir, the router a Python session on a free port.

    identities and certs write the secrets, the router loads the ACL with mutual TLS, the
    planner serves as its client, its healthcheck passes, then the injector plays the
    contingency while the fleet drives to arrival (both at 10x, here only), each through
    its own certificate.
    """
    from tests.zenoh_util import free_port

    port = free_port()
    here = f"127.0.0.1:{port}"

    def local(argv: list[str]) -> list[str]:
        swap = ((SECRETS, str(tmp_path)), ("router:7447", here), ("/var/lib/pfp", str(tmp_path / "state")))
        for a, b in swap:
            argv = [x.replace(a, b) for x in argv]
        return argv

    def pfp(argv: list[str], **kw) -> subprocess.Popen:
        assert argv[0] == "pfp"
        return subprocess.Popen([sys.executable, "-m", "pfp_service", *argv[1:]], cwd=ROOT, **kw)

    assert pfp_main([*local(_argv(SERVICES["identities"]))[1:], "--quiet"]) == 0
    certs = local(_argv(SERVICES["certs"]))
    assert subprocess.run([sys.executable, *certs[1:]], cwd=ROOT, capture_output=True).returncode == 0
    conf = zenoh.Config.from_file(str(tmp_path / "zenoh-router-mtls.json5"))
    conf.insert_json5("listen/endpoints", json.dumps([f"tls/{here}"]))
    router = zenoh.open(conf)
    log = (tmp_path / "planner.log").open("w")
    planner = pfp(local(_argv(SERVICES["planner"])), stdout=log, stderr=subprocess.STDOUT)
    try:
        health = local(SERVICES["planner"]["healthcheck"]["test"][1:])
        for _ in range(60):
            if pfp(health, stdout=subprocess.DEVNULL).wait(timeout=30) == 0:
                break
        else:
            pytest.fail("the planner never became healthy: " + (tmp_path / "planner.log").read_text()[-2000:])
        fast = ["--speed-up", "10"]
        injector = pfp([*local(_argv(SERVICES["injector"])), *fast], stdout=subprocess.PIPE, text=True)
        fleet_argv = [*local(_argv(SERVICES["fleet"])), *fast, "--duration-s", "120"]
        fleet = pfp(fleet_argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        fleet_out, _ = fleet.communicate(timeout=180)
        inject_out, _ = injector.communicate(timeout=60)
        assert fleet.returncode == 0, fleet_out[-3000:]
        assert injector.returncode == 0, inject_out[-3000:]
        assert "Traceback" not in (tmp_path / "planner.log").read_text()
    finally:
        planner.terminate()
        planner.wait(timeout=20)
        log.close()
        router.close()


@pytest.mark.parametrize("name", ["zenoh-router.json5", "zenoh-router-mtls.json5"])
def test_the_shipped_router_config_itself_denies_a_spoof(name, secrets_volume):
    """docker/'s file as shipped (only /etc/pfp -> the secrets the one-shots wrote, and a free port)."""
    from tests.zenoh_util import Inbox, free_port, put_json

    tls = "mtls" in name
    port = free_port()
    text = (DOCKER / name).read_text().replace(SECRETS, str(secrets_volume))
    conf = zenoh.Config.from_json5(text)
    conf.insert_json5("listen/endpoints", json.dumps([f"{'tls' if tls else 'tcp'}/127.0.0.1:{port}"]))
    router = zenoh.open(conf)

    def as_(who: str) -> zenoh.Session:
        path = secrets_volume / "clients" / f"{who}{'-tls' if tls else ''}.json5"
        c = zenoh.Config.from_json5(path.read_text().replace(SECRETS, str(secrets_volume)))
        c.insert_json5("connect/endpoints", json.dumps([f"{'tls' if tls else 'tcp'}/127.0.0.1:{port}"]))
        return zenoh.open(c)

    sessions = [as_("planner"), as_("unit-m1"), as_("unit-m2")]
    try:
        planner, m1, m2 = sessions
        inbox = Inbox(planner, "mumt/default/unit/*/state")
        time.sleep(0.3)  # the subscription reaches the router
        put_json(m2, "mumt/default/unit/m1/state", {"position": [9, 9], "seq": 666})
        put_json(m1, "mumt/default/unit/m1/state", {"position": [1, 1], "seq": 1})
        assert inbox.get()["seq"] == 1
        with pytest.raises(TimeoutError):
            inbox.get(timeout=0.6)
    finally:
        for s in sessions:
            s.close()
        router.close()

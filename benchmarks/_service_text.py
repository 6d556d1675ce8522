"""``pfp bench service``'s figures as text for people: the steady rows (a row per state key), the phases, the targets."""

from __future__ import annotations

from typing import Any

from benchmarks._service_teams import print_teams

__all__ = ["print_doc"]


def _per_state_us(st: dict[str, Any]) -> float | None:
    """CPU microseconds per state answered (cpu_percent of one core over answered_per_s)."""
    cpu, rate = st.get("cpu_percent"), st.get("answered_per_s")
    return None if cpu is None or not rate else 1e4 * cpu / rate


def _f(v: float | None, fmt: str = ".2f") -> str:
    return "-" if v is None else format(v, fmt)


def print_doc(doc: dict[str, Any]) -> None:
    """The whole run, as ``pfp bench service`` prints it without ``--json``."""
    m, ld = doc["machine"], doc["load"]
    print(
        f"pfp bench service on {m['arch']}, {m['cpu']}, {m['cores']} cores, Python {m['python']}, zenoh {m['zenoh']}, "
        f"tree {m['tree']}, load avg {[round(x, 1) for x in m['loadavg_at_start'] or []]}"
    )
    print(
        f"  {ld['units']} units x {ld['rate_hz']:g} Hz = {ld['offered_per_s']:g}/s offered, {ld['threats']} threats, escape {ld['escape']}; {ld['via']}"
    )
    for kind in ("echo", "planner"):
        r = doc.get(kind)
        if r is None:
            continue
        st = r["steady"]
        after = r.get("steady_after", {}).get("deliberations")
        first = (
            ""
            if after is None
            else f" (after the storm's deliberations: {'landed' if after['landed'] else 'NOT landed'}, waited {after['waited_s']:.1f} s)"
        )
        print(f"\n[{kind}] steady {ld['duration_s']:g} s{first}:")
        print(
            f"  latency p50 {_f(st['p50_ms'], '.3f')} ms, p90 {_f(st['p90_ms'], '.3f')}, p99 {_f(st['p99_ms'], '.3f')}, max {_f(st['max_ms'], '.1f')}"
        )
        print(
            f"  input {st['input_per_s']:.0f}/s, output {st['output_per_s']:.0f}/s, unanswered {100 * st['unanswered_fraction']:.3f} %"
        )
        print(
            f"  CPU {_f(st['cpu_percent'], '.0f')} % over {st.get('processes', 1)} processes (load generator {_f(st['generator_cpu_percent'], '.0f')} %, load avg {_f(st['loadavg'], '.1f')}), RSS {_f(st['rss_mb'], '.0f')} MB, peak {_f(r['final_memory']['peak_rss_mb'], '.0f')} MB; statuses {st['statuses']}"
        )
        by_key = dict(r.get("steady_by_key", {}))
        if "mixed" in by_key:  # each half of the same run, with the run's CPU and load
            mixed = by_key.pop("mixed")
            for k, half in mixed.get("by_key", {}).items():
                by_key[f"{k} (mixed)"] = {
                    **half,
                    "answered_per_s": half["answered"] / mixed["spent_s"],
                    "cpu_percent": mixed["cpu_percent"],
                    "loadavg": mixed["loadavg"],
                }
        if len(by_key) > 1:
            print("  state key      p50 ms   p90 ms   p99 ms   unanswered  answered/s  CPU %  load avg")
            for key, ks in by_key.items():
                print(
                    f"  {key:<13}  {_f(ks['p50_ms'], '.3f'):>6}  {_f(ks['p90_ms'], '.3f'):>7}  {_f(ks['p99_ms'], '.3f'):>7}"
                    f"  {100 * ks['unanswered_fraction']:>8.3f} %  {ks['answered_per_s']:>10.0f}  {_f(ks['cpu_percent'], '.0f'):>5}"
                    f"  {_f(ks['loadavg'], '.1f'):>8}"
                )
        if "cpu_rate" in r:
            c = r["cpu_rate"]
            landed = c.get("deliberations")
            note = (
                ""
                if landed is None
                else f"; deliberations {'landed' if landed['landed'] else 'NOT landed'} first"
            )
            print(
                f"  at {c['input_per_s']:.0f}/s: CPU {_f(c['cpu_percent'], '.0f')} % over {c.get('processes', 1)} processes, "
                f"{_f(_per_state_us(c), '.0f')} us per state answered, p50 {_f(c['p50_ms'], '.3f')} ms, p99 {_f(c['p99_ms'], '.2f')} ms, "
                f"unanswered {100 * c['unanswered_fraction']:.3f} % (load avg {_f(c['loadavg'], '.1f')}){note}"
            )
        if "storm" in r:
            s = r["storm"]
            b = s["bystander"]
            print(
                f"  goal storm: {s['guided']}/{s['goals']} guided, all in {_f(s['all_guided_s'], '.3f')} s (p50 {_f(s['guided_p50_s'], '.3f')} s); "
                f"deliberations {s['deliberations_ended']}/{s['deliberations_started']} ended, all in {_f(s['all_deliberated_s'], '.2f')} s; "
                f"bystander p99 {_f(b['p99_ms'], '.1f')} ms, max {_f(b['max_ms'], '.1f')} ms, unanswered {100 * b['unanswered_fraction']:.1f} %"
            )
        if "fanout" in r:
            f = r["fanout"]
            print(
                f"  fan-out: {f['redirected']}/{f['affected']} re-directed, all in {_f(f['all_redirected_ms'], '.1f')} ms (p50 {_f(f['redirected_p50_ms'], '.1f')}); "
                f"deliberations {f['deliberations_ended']}/{f['deliberations_started']}, all in {_f(f['all_deliberated_s'], '.2f')} s; "
                f"pushes sent {f['pushes_sent']} (first copies {f['pushes_first_copies']}, re-sent {f['pushes_resent']}), delivered {f['pushes_delivered']}"
            )
        if "forget" in r:
            fg = r["forget"]
            print(
                f"  forgotten: {fg['units_left']} units left after {_f(fg['all_forgotten_s'], '.1f')} s; RSS "
                f"{_f(fg['rss_before_mb'], '.0f')} -> {_f(fg['rss_after_mb'], '.0f')} MB (idle {_f(fg['idle_rss_mb'], '.0f')} MB)"
            )
        if "find_max" in r:
            fm = r["find_max"]
            short = f" ({fm['short_probes']} probes could not offer their rate)" if fm["short_probes"] else ""
            dl = fm.get("deliberations")
            landed = ""
            if dl is not None:
                state = "landed" if dl["landed"] else f"NOT landed ({dl['left']} left)"
                landed = f"; deliberations {state} after {dl['waited_s']:.1f} s"
            print(
                f"  find-max: {_f(fm['max_per_s'], '.0f')}/s ({_f(fm['max_rate_hz'], '.2f')} Hz per unit){short}{landed}"
            )
            for pr in fm["probes"]:
                print(
                    f"    {pr['offered_per_s']:>8.0f}/s: p99 {_f(pr['p99_ms'], '.2f')} ms, unanswered {100 * pr['unanswered_fraction']:.2f} %, CPU {_f(pr['cpu_percent'], '.0f')} % {'ok' if pr['ok'] else 'fail'}"
                )
        ex = r["exit"]
        if ex["error_lines"]:
            print(f"  {kind} log: {ex['error_lines']} error lines, first: {ex['first_errors'][:2]}")
    if "scale_out" in doc:
        _print_scale_out(doc["scale_out"], ld)
    if "teams" in doc:
        print_teams(doc["teams"])
    print()
    for t in doc["targets"]:
        flag = "n/a" if t["met"] is None else ("ok" if t["met"] else "MISSED")
        note = f"; {t['note']}" if "note" in t else ""
        print(f"  [{flag}] {t['target']}: {_f(t['measured'], '.4g')} (limit {t['limit']:g}{note})")


def _print_scale_out(so: dict[str, Any], ld: dict[str, Any]) -> None:
    print(f"\n[scale-out] steady {ld['duration_s']:g} s, 1 vs {so['planners']} planners; {so['via']}:")
    print(
        "  planners  answered/s  p50 ms   p99 ms   unanswered  answered twice  units by two  CPU % (all)  units per planner"
    )
    for r in so["runs"]:
        st = r["steady"]
        print(
            f"  {r['planners']:>8}  {st['answered_per_s']:>10.0f}  {_f(st['p50_ms'], '.2f'):>7}  {_f(st['p99_ms'], '.1f'):>7}"
            f"  {100 * st['unanswered_fraction']:>9.2f} %  {st['answered_twice']:>14}  {st['units_answered_by_two']:>12}"
            f"  {_f(st['cpu_percent'], '.0f'):>11}  {st['units_per_planner']}"
        )
        cpu = ", ".join(f"{k} {_f(v, '.0f')} %" for k, v in st["cpu_percent_by_process"].items())
        print(f"            CPU by process (each with its workers): {cpu}")
        got = ", ".join(f"{k} {v}" for k, v in st.get("states_by_planner", {}).items())
        if got:
            print(
                f"            states applied by planner (of {st['sent']} sent): {got}; largest share {_f(st['states_share_max'], '.3f')}"
            )
    v = so["vs_one"]
    print(
        f"  {so['planners']} vs 1: answered/s x{_f(v['answered_per_s'], '.2f')}, p50 x{_f(v['p50_ms'], '.2f')}, "
        f"p99 x{_f(v['p99_ms'], '.2f')}, CPU x{_f(v['cpu_percent'], '.2f')} (load avg {_f(so['runs'][-1]['steady']['loadavg'], '.1f')})"
    )

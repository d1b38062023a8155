"""Run named benchmark cases, interleaved, and print their figures as Markdown.

    python bench/run.py --list                              # the cases, one line each
    python bench/run.py --describe e2e                      # what a case measures and its options
    python bench/run.py ring_latency render_fps --rounds 3  # both cases, rounds interleaved
    python bench/run.py e2e --tree main=../main --tree new=. --rounds 6 --opt duration=30   # A/B of trees
    python bench/run.py e2e --variant rig=sensor.method=camera_rig --variant beams=sensor.method=beam_native
    python bench/run.py mock_cast --quick --json mock.json                                       # a check, seconds

Each sample (one case, one arm, one round) is taken in a fresh process that imports the arm's source tree
(``--tree NAME=PATH``; default this checkout); ``--variant NAME=PATH=VALUE`` adds an arm of this tree with one more
scenario setting (a name given again adds its setting to that arm). Round r runs the cases and their arms in order
when r is even and reversed when it is odd. The Markdown names the command, the machine, the load average before
and after, and per case the medians over the rounds (min-max) and each arm's paired ratio to the first arm.
Figures for the record go to bench/HISTORY.md under a dated heading; ``python bench/run_all.py`` writes the
headline figures to bench/results.md.
"""
from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parent
if str(BENCH) not in sys.path:
    sys.path.insert(0, str(BENCH))

from harness import OptionError, load_cases, parse_arms, parse_value, run_cases  # noqa: E402
from harness.arms import ROOT, worker_main  # noqa: E402
from harness.report import markdown, write_json  # noqa: E402

__all__ = ["main", "parse_opts"]


def parse_opts(given: list[str], names: list[str], cases: dict) -> dict[str, dict]:
    """``[CASE.]NAME=VALUE`` strings -> {case: {name: value}}; a NAME without a case goes to every case named on
    the command line that has that option (at least one must)."""
    out: dict[str, dict] = {n: {} for n in names}
    for g in given:
        key, sep, value = g.partition("=")
        if not sep:
            raise OptionError(f"--opt {g!r}: expected [CASE.]NAME=VALUE")
        target, dot, name = key.rpartition(".")
        targets = [target] if dot else [n for n in names if name in cases[n].options]
        if dot and target not in names:
            raise OptionError(f"--opt {g!r}: case {target!r} is not among those run ({', '.join(names)})")
        if not targets:
            raise OptionError(f"--opt {g!r}: none of {', '.join(names)} has an option {name!r} "
                              "(`python bench/run.py --describe CASE` lists them)")
        for t in targets:
            out[t][name] = parse_value(value)
    return out


def _describe(case) -> str:
    opts = "\n".join(f"  {k} = {v!r}" + (f"   (--quick: {case.quick[k]!r})" if k in case.quick else "")
                     for k, v in case.options.items()) or "  (none)"
    return (f"{case.name}: {case.summary}\n\n{case.notes}\n\ndefault rounds: {case.rounds}; scenario settings "
            f"(--set, --variant): {'yes' if case.settings else 'no'}\noptions (--opt NAME=VALUE):\n{opts}")


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--worker"]:
        return worker_main(argv[1])
    if str(ROOT) not in sys.path:                               # in-process samples import this checkout
        sys.path.insert(1, str(ROOT))
    ap = argparse.ArgumentParser(prog="python bench/run.py", description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__.split("\n\n", 1)[1])
    ap.add_argument("cases", nargs="*", metavar="CASE")
    ap.add_argument("--list", action="store_true", help="list the cases, one line each")
    ap.add_argument("--describe", metavar="CASE", help="what CASE measures and its options")
    ap.add_argument("--rounds", type=int, help="interleaved rounds of every case (default: each case's own)")
    ap.add_argument("--quick", action="store_true", help="a check of the cases in seconds, not their figures")
    ap.add_argument("--tree", action="append", default=[], metavar="NAME=PATH", help="a source tree to measure "
                    "(repeatable: A/B; the first is the baseline of the ratios)")
    ap.add_argument("--variant", action="append", default=[], metavar="NAME=PATH=VALUE",
                    help="this tree with one more scenario setting, as one arm (repeatable)")
    ap.add_argument("--set", action="append", default=[], metavar="PATH=VALUE", help="a scenario setting of every arm")
    ap.add_argument("--opt", action="append", default=[], metavar="[CASE.]NAME=VALUE", help="a case's option")
    ap.add_argument("--json", type=Path, metavar="FILE", help="also write every sample and figure as JSON")
    ap.add_argument("--in-process", action="store_true", help="measure in this process (debugging; no --tree)")
    a = ap.parse_args(argv)
    try:
        cases = load_cases()
        if a.list:
            width = max(len(n) for n in cases)
            print("\n".join(f"{n:<{width}}  {cases[n].summary}" for n in sorted(cases)))
            return 0
        if a.describe:
            if a.describe not in cases:
                raise OptionError(f"no case named {a.describe!r}; `python bench/run.py --list` lists them")
            print(_describe(cases[a.describe]))
            return 0
        if not a.cases:
            ap.error("name at least one case (`--list` lists them)")
        unknown = [n for n in a.cases if n not in cases]
        if unknown:
            raise OptionError(f"no case named {', '.join(map(repr, unknown))}; `python bench/run.py --list` lists them")
        arms = parse_arms(a.tree, a.variant)
        if a.in_process and any(arm.tree != ROOT for arm in arms):
            raise OptionError("--in-process measures this checkout only: leave --tree out")
        fixed = [n for n in a.cases if not cases[n].settings]
        if (a.set or any(arm.settings for arm in arms)) and fixed:
            raise OptionError(f"{', '.join(fixed)} run(s) no scenario: --set and --variant do not apply")
        opts = parse_opts(a.opt, a.cases, cases)
        for n in a.cases:
            cases[n].resolve(a.quick, opts[n])                  # unknown options refused before anything runs
        command = "python bench/run.py " + shlex.join(argv)
        session = run_cases([cases[n] for n in a.cases], arms, rounds=a.rounds, quick=a.quick, opts=opts,
                            settings=a.set, in_process=a.in_process, command=command)
    except OptionError as exc:
        print(f"bench/run.py: {exc}", file=sys.stderr)
        return 2
    print(markdown(session))
    if a.json:
        write_json(session, a.json)
    return 1 if session.failed else 0


if __name__ == "__main__":
    sys.exit(main())

"""Sweep files: parse, validate whole, expand into runs (docs/sweeps.md).

``load_sweep(path)`` reads the YAML with line marks (cosim/scenario/yamlmarks.py), validates its structure
(:class:`cosim.scenario.config.sweep.SweepFile`), then builds and validates every run's scenario with the
scenario loader before anything starts: each override goes to the loader as a ``--set`` entry, and every problem
the loader finds in one (unknown field, wrong type, out of range) is reported at the line of the sweep file that
gave the value. Problems are raised together as one :class:`cosim.errors.ScenarioError`.

A run is identified by ``<slug>-s<seed>-<hash>``: the slug names the varied values (readable, shortened), the
hash (8 hex) is of the base, the fixed overrides, the varied values and the seed, so the same run keeps its id
(and its directory) across invocations, which is what resuming relies on.
"""
from __future__ import annotations

import hashlib
import itertools
import json
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydantic import ValidationError

from cosim.errors import Problem, ScenarioError
from cosim.scenario.config import Scenario
from cosim.scenario.config.sweep import MAX_RUNS, SWEEP_FORMAT_VERSION, Distribution, SweepFile
from cosim.scenario.files import MAX_SCENARIO_BYTES, packaged_scenarios, read_scenario
from cosim.scenario.loader import SET_FILE, load_scenario_text, path_fields, resolve_scenario_arg
from cosim.scenario.values import value_problems
from cosim.scenario.yamlmarks import Doc, Mark, dotted, parse, show

__all__ = ["Override", "RunSpec", "Sweep", "load_sweep", "build_runs", "run_id", "sample"]

SLUG_CHARS = 48  # readable part of a run id
_UNSAFE = re.compile(r"[^A-Za-z0-9._=+-]+")
_UNION_TAG = re.compile(r"[\[\]-]")
_PATH_FIELDS = {".".join(loc) for loc in path_fields()}
#: the loader's messages about an override's path rather than its value (reported at the sweep file's key)
_PATH_PROBLEMS = ("unknown key", "malformed override", "cannot set a key", "'")


@dataclass(frozen=True)
class Override:
    """One scenario override: dotted ``path``, ``value``, and where the sweep file gave it: the value (``mark``,
    ``where``) and its key (``key_mark``, ``key_where``: where an unknown field is reported)."""

    path: str
    value: object
    mark: Mark
    where: str
    key_mark: Mark | None = None
    key_where: str = ""


@dataclass(frozen=True)
class RunSpec:
    """One run of a sweep: its stable ``id``, the varied values (``params``, dotted path -> value), the seed, the
    validated scenario, and ``labels`` (extra table columns, e.g. a study's knob and setting)."""

    id: str
    params: dict
    seed: int
    scenario: Scenario
    labels: dict = field(default_factory=dict)

    @property
    def needs_gl(self) -> bool:
        """Whether the run draws with OpenGL (it must go to a worker with the EGL resource)."""
        return self.scenario.renderer == "gl" and "renderer" in self.scenario.participants

    @property
    def cores(self) -> int:
        """Cores the run keeps busy: 1 per process, but a ring that renders or perceives takes about 2."""
        return 1 if len(self.scenario.participants) == 1 else 2


@dataclass(frozen=True)
class Sweep:
    """A validated sweep: its name, the varied parameters (table columns, in file order) and the runs."""

    name: str
    parameters: tuple[str, ...]
    runs: tuple[RunSpec, ...]
    labels: tuple[str, ...] = ()


def run_id(base: str, fixed: dict, params: dict, seed: int) -> str:
    """``<slug>-s<seed>-<hash8>``: readable varied values plus a hash of everything that defines the run."""
    key = json.dumps({"base": base, "set": fixed, "params": params, "seed": seed}, sort_keys=True, default=str)
    digest = hashlib.sha1(key.encode()).hexdigest()[:8]
    parts = [f"{p.rsplit('.', 1)[-1]}={v:.4g}" if isinstance(v, float) else f"{p.rsplit('.', 1)[-1]}={v}"
             for p, v in params.items()]
    slug = _UNSAFE.sub("_", "_".join(parts))[:SLUG_CHARS].strip("_.") or "run"
    return f"{slug}-s{seed}-{digest}"


def sample(dist: Distribution, rng: np.random.Generator) -> list:
    """``dist.count`` values drawn from ``dist`` (plain Python numbers, or items of ``values`` for choice)."""
    n = dist.count
    if dist.distribution == "uniform":
        return [float(x) for x in rng.uniform(dist.low, dist.high, n)]
    if dist.distribution == "loguniform":
        return [float(x) for x in np.exp(rng.uniform(np.log(dist.low), np.log(dist.high), n))]
    if dist.distribution == "normal":
        return [float(x) for x in rng.normal(dist.mean, dist.std, n)]
    return [dist.values[int(i)] for i in rng.integers(0, len(dist.values), n)]


# ------------------------------------------------------------------------------------------ structure
def _structure_problem(err: dict, doc: Doc) -> Problem:
    """A pydantic error of the SweepFile record at the line of the node it names."""
    loc = tuple(p for i, p in enumerate(err["loc"])
                if not (isinstance(p, str) and _UNION_TAG.search(p) and i < len(err["loc"]) - 1))
    found = loc
    while found and found not in doc.values:
        found = found[:-1]
    root = doc.values[()]
    msg = err["msg"].replace("an object", "a mapping").replace("a valid dictionary", "a mapping")
    if err["type"] == "extra_forbidden":
        mark = doc.keys.get(loc, root)
        msg = f"unknown key '{loc[-1]}'" + ("" if len(loc) > 1 else
                                          f"; allowed: {', '.join(SweepFile.model_fields)}")
    elif err["type"] == "missing":
        mark, msg = doc.keys.get(found, root), f"missing required key '{loc[-1]}'"
    elif msg.startswith("Value error, "):
        mark, msg = doc.keys.get(found, root), msg.split(", ", 1)[1]
    else:
        mark = doc.values.get(found, root)
        if "input" in err and not isinstance(err["input"], (dict, list)):
            msg += f", got {show(err['input'])}"
    return Problem(mark.file, mark.line, mark.col, dotted(loc), msg)


def _check_lengths(doc: Doc, section: str, lengths: dict[str, int], what: str) -> None:
    """Problems for every entry of ``section`` whose length differs from the first's."""
    if not lengths:
        return
    first, n = next(iter(lengths.items()))
    for key, m in lengths.items():
        if m != n:
            doc.problem(doc.keys[(section, key)], (section, key),
                        f"{section} parameters are varied together, so their {what} must be equal: "
                        f"'{key}' has {m}, '{first}' has {n}")


def _parse_structure(text: str, filename: str) -> tuple[Doc, SweepFile | None]:
    if len(text) > MAX_SCENARIO_BYTES:
        raise ScenarioError([Problem(filename, 1, 1, "", f"the sweep file is {len(text) / 2**20:.1f} MiB; sweep "
                                     f"files are limited to {MAX_SCENARIO_BYTES >> 20} MiB")])
    doc = parse(text, filename)
    if doc.problems and not doc.values:
        raise ScenarioError(doc.problems)
    if not isinstance(doc.data, dict):
        doc.problem(doc.values[()], (), "the top level of a sweep file must be a mapping")
        raise ScenarioError(doc.problems)
    version = doc.data.get("format_version")
    if version != SWEEP_FORMAT_VERSION:
        mark = doc.values.get(("format_version",), doc.values[()])
        doc.problem(mark, ("format_version",), f"unsupported or missing format_version {show(version)}; this "
                    f"version of graincosim reads sweep files with format_version: {SWEEP_FORMAT_VERSION}")
        raise ScenarioError(doc.problems)
    refused = {dotted(loc) for loc in value_problems(doc)}       # NaN, huge integers, control characters
    try:
        spec = SweepFile.model_validate_json(json.dumps(doc.data))
    except ValidationError as e:
        found = [_structure_problem(err, doc) for err in e.errors(include_url=False)]
        doc.problems += [p for p in found if p.path not in refused]
        spec = None
    if spec is not None:
        _check_lengths(doc, "zip", {k: len(v) for k, v in spec.zip.items()}, "lengths")
        _check_lengths(doc, "random", {k: d.count for k, d in spec.random.items()}, "counts")
        seen: dict[str, str] = {}
        for section in ("set", "grid", "zip", "random"):
            for key in getattr(spec, section):
                if key in seen or key == "seed":
                    doc.problem(doc.keys[(section, key)], (section, key), "the seed is set by 'seeds'" if key == "seed"
                                else f"'{key}' is already given in '{seen[key]}'")
                seen.setdefault(key, section)
    return doc, spec


# ------------------------------------------------------------------------------------------ expansion
def _points(doc: Doc, spec: SweepFile) -> list[list[Override]]:
    """Every combination of the varied values, each as its overrides (grid x zip x random)."""
    def over(section: str, key: str, i: int, value) -> Override:
        loc = (section, key, i) if (section, key, i) in doc.values else (section, key)
        return Override(key, value, doc.values[loc], dotted(loc), doc.keys[(section, key)], f"{section}.{key}")

    axes = [[over("grid", k, i, v) for i, v in enumerate(vals)] for k, vals in spec.grid.items()]
    if spec.zip:
        n = min(len(v) for v in spec.zip.values())  # unequal lengths are reported; the rest is still checked
        axes.append([[over("zip", k, i, vals[i]) for k, vals in spec.zip.items()] for i in range(n)])
    if spec.random:
        rng = np.random.default_rng(spec.sample_seed)
        drawn = {k: sample(d, rng) for k, d in spec.random.items()}
        n = min(d.count for d in spec.random.values())
        axes.append([[Override(k, drawn[k][i], doc.keys[("random", k)], f"random.{k} (value {drawn[k][i]!r})",
                               doc.keys[("random", k)], f"random.{k}") for k in spec.random] for i in range(n)])
    points = []
    for combo in itertools.product(*axes):
        points.append([o for item in combo for o in (item if isinstance(item, list) else [item])])
    return points


def _as_set(o: Override, base_dir: Path) -> str:
    value = o.value
    if o.path in _PATH_FIELDS and isinstance(value, str) and not os.path.isabs(value):
        value = str((base_dir / value).resolve())  # relative to the sweep file, not the working directory
    return f"{o.path}={json.dumps(value)}"


def _run_count(spec: SweepFile) -> int:
    """Runs the sweep expands to: grid lengths x zip length x random count x seeds (an empty section counts 1)."""
    total = len(spec.seeds) if isinstance(spec.seeds, list) else spec.seeds
    for values in spec.grid.values():
        total *= len(values)
    if spec.zip:
        total *= min(len(v) for v in spec.zip.values())
    if spec.random:
        total *= min(d.count for d in spec.random.values())
    return total


def build_runs(base_text: str, base_file: str, base_label: str, fixed: list[Override],
               points: list[list[Override]], seeds: list[Override], sweep_dir: Path,
               labels: list[dict] | None = None, plugin_dir: str | None = None) -> tuple[list[RunSpec], list[Problem]]:
    """Validate every run's scenario (base + fixed + point + seed) with the scenario loader; problems in an
    override are reported at its sweep-file mark. ``plugin_dir``: where the runs' plug-in modules are looked for
    first (default: the base file's folder). Returns (runs, problems)."""
    runs, problems = [], set()
    fixed_plain = {o.path: o.value for o in fixed}
    base_dir = Path(base_file).resolve().parent
    for j, point in enumerate(points):
        for seed in seeds:
            items = [*fixed, *point, seed]
            try:
                scenario = load_scenario_text(base_text, base_file, [_as_set(o, sweep_dir) for o in items],
                                              base_dir=base_dir, extra={"plugin_dir": plugin_dir})
            except ScenarioError as exc:
                for p in exc.problems:
                    if p.file == SET_FILE and 1 <= p.line <= len(items):
                        o = items[p.line - 1]
                        if p.message.startswith(_PATH_PROBLEMS) and o.key_mark is not None:
                            p = Problem(o.key_mark.file, o.key_mark.line, o.key_mark.col, o.key_where, p.message)
                        else:
                            p = Problem(o.mark.file, o.mark.line, o.mark.col, o.where, p.message)
                    problems.add(p)
                continue
            params = {o.path: o.value for o in point}
            named = {**labels[j], **params} if labels else params          # a suite's runs are named by case
            runs.append(RunSpec(run_id(base_label, fixed_plain, named, seed.value), params, seed.value, scenario,
                                dict(labels[j]) if labels else {}))
    return runs, sorted(problems, key=lambda p: (p.file != seeds[0].mark.file, p.file, p.line, p.col, p.path))


def load_sweep(path: str | os.PathLike) -> Sweep:
    """Read, validate and expand the sweep file ``path``; raise ScenarioError with every problem found."""
    path = Path(path)
    try:
        size = os.stat(path).st_size
        if size > MAX_SCENARIO_BYTES:
            raise ScenarioError([Problem(str(path), 1, 1, "", f"the sweep file is {size / 2**20:.1f} MiB; sweep "
                                         f"files are limited to {MAX_SCENARIO_BYTES >> 20} MiB")])
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise ScenarioError([Problem(str(path), 0, 0, "", f"cannot read sweep file: {e}")]) from None
    doc, spec = _parse_structure(text, str(path))
    if spec is None:
        raise ScenarioError(doc.problems)
    names = spec.base if isinstance(spec.base, list) else [spec.base]
    bases = [_resolve_base(path, doc, name, ("base", i) if isinstance(spec.base, list) else ("base",))
             for i, name in enumerate(names)]
    fixed = [Override(k, v, doc.values[("set", k)], f"set.{k}", doc.keys[("set", k)], f"set.{k}")
             for k, v in spec.set.items()]
    total = _run_count(spec) * len(bases)
    if total > MAX_RUNS:                     # counted before anything is expanded or drawn
        m = doc.values[()]
        raise ScenarioError([Problem(m.file, m.line, m.col, "", f"{total:,} runs: a sweep has at most "
                                     f"{MAX_RUNS:,} (grid lengths x zip length x random count x seeds)")])
    points = _points(doc, spec)
    seed_loc = lambda i: ("seeds", i) if isinstance(spec.seeds, list) else ("seeds",)  # noqa: E731
    seeds = [Override("seed", s, doc.values.get(seed_loc(i), doc.values[()]), dotted(seed_loc(i)))
             for i, s in enumerate(spec.seed_list)]
    # plug-in modules beside the sweep file are found when the base is a packaged scenario (a base file's own
    # folder is searched for its plug-ins otherwise), unless the sweep sets plugin_dir itself
    runs, problems = [], []
    packaged_files = {p.resolve() for p in packaged_scenarios().values()}
    for name, base in zip(names, bases):
        packaged = base.resolve() in packaged_files
        plugin_dir = str(path.parent.resolve()) if packaged and "plugin_dir" not in spec.set else None
        labels = [{"base": name}] * len(points) if len(bases) > 1 else None
        r, p = build_runs(read_scenario(base), str(base), name, fixed, points, seeds, path.parent.resolve(),
                          labels=labels, plugin_dir=plugin_dir)
        runs += r
        problems += [q for q in p if q not in problems]
    seen = {(p.file, p.line, p.col) for p in doc.problems}      # a value refused as such is reported once
    problems = sorted(set(doc.problems) | {p for p in problems if (p.file, p.line, p.col) not in seen},
                      key=lambda p: (p.file != str(path), p.file, p.line, p.col))
    ids = [r.id for r in runs]
    if not problems and len(set(ids)) != len(ids):
        dup = next(i for i in ids if ids.count(i) > 1)
        problems.append(Problem(str(path), 1, 1, "", f"two runs have the same parameters and seed ({dup}): "
                                "a value is repeated"))
    if problems:
        raise ScenarioError(problems)
    return Sweep(spec.name or path.stem, tuple(spec.grid) + tuple(spec.zip) + tuple(spec.random), tuple(runs),
                 ("base",) if len(bases) > 1 else ())


def _resolve_base(path: Path, doc: Doc, name: str, loc: tuple) -> Path:
    """The scenario file of base ``name`` (a packaged name or a path relative to the sweep file ``path``);
    ScenarioError at its mark ``loc`` when there is none."""
    arg = name if (path.parent / name).suffix == "" else str(path.parent / name)
    try:
        return resolve_scenario_arg(arg)
    except ScenarioError:
        m = doc.values.get(loc, doc.values[()])
        raise ScenarioError([Problem(m.file, m.line, m.col, dotted(loc), f"no such packaged scenario or file "
                                     f"{name!r} (a path is relative to the sweep file)")]) from None

"""A fuzz test that ships: >= 1000 mutated scenario, trace and start files built (seeded) from
the files in ``scenarios/``, each validated as ``dispatch validate`` does (``cli.main`` in this
process, output captured). Each gives ``ok`` (exit 0) or one error line (exit 2, a
DispatchError); any other exception fails the test.

The ``slow`` part runs (``dispatch run``, one run per file: the first of its sweep) every file
that validates, in a subprocess under a time limit (30 CPU seconds, 120 s wall) and a memory
limit (2 GiB resident, the child's own peak read by ``wait4``; 8 GiB of address space as a
backstop): no traceback, no hang, no blow-up.

Mutations: wrong types, missing and unknown keys, huge / negative / zero / NaN / inf numbers,
seeds past int64, sections swapped, renamed or replaced by a scalar, deep nesting, bad
encodings (UTF-16/32, Latin-1, stray bytes), truncated files, duplicated lines, plugin names
and parameters (rejected ones included), checkpoints that are not checkpoints, and mutated
trace and start files (missing columns, bad cells, NaN, negative times, unknown nodes,
duplicate ids, binary junk, empty files).
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import time
import tomllib
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from dispatch.files.traces import SHIPPED_TRACES, shipped_trace
from dispatch.run import cli
from tests.conftest import ROOT

SCENARIOS = ROOT / "scenarios"
N_FILES = 1100
SEED = 20261123
RUN_CPU_S = 30  # a hang is judged by CPU time: on a loaded machine wall time says little
RUN_TIMEOUT_S = 4 * RUN_CPU_S  # wall: a run blocked without using CPU is a hang too
RUN_MEMORY_BYTES = 2 * 2**30  # resident: a run past it is a memory blow-up
# address space, a backstop only: numba's LLVM, pyarrow's pools and the threads' stacks reserve
# about 2 GiB of it in a ten-task voxel run that keeps under 0.3 GiB resident
RUN_ADDRESS_BYTES = 8 * 2**30
MAX_SHIP_DURATION = 600.0  # bases are shortened so that a run that validates is quick

# ----------------------------------------------------------------------------- a TOML writer

_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(k: str) -> str:
    return k if _BARE.match(k) else json.dumps(k)


class Deep:
    """A list nested ``depth`` deep (written without recursion)."""

    def __init__(self, depth: int) -> None:
        self.depth = depth


def _value(v) -> str:
    if isinstance(v, Deep):
        return "[" * v.depth + "]" * v.depth
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))


def dumps(doc: dict, prefix: str = "") -> str:
    """TOML text of a document (scalars first, then sub-tables as sections)."""
    lines = [f"{_key(k)} = {_value(v)}" for k, v in doc.items() if not isinstance(v, dict)]
    out = "\n".join(lines) + ("\n" if lines else "")
    for k, v in doc.items():
        if isinstance(v, dict):
            name = f"{prefix}{_key(k)}"
            scalars = {a: b for a, b in v.items() if not isinstance(b, dict)}
            out += f"\n[{name}]\n" + "".join(f"{_key(a)} = {_value(b)}\n"
                                            for a, b in scalars.items())
            out += dumps({a: b for a, b in v.items() if isinstance(b, dict)}, name + ".")
    return out


# ----------------------------------------------------------------------------- the generator


@dataclass
class Case:
    index: int
    path: Path
    mutation: str
    outcome: str = ""  # ok | error | crash
    message: str = ""
    overrides: list[str] = field(default_factory=list)  # to run the first run of the sweep


def _bases() -> dict[str, dict]:
    """The shipped scenarios, shortened (duration, fleet) so that a run of one is quick."""
    bases = {}
    for p in sorted(SCENARIOS.glob("*.toml")):
        doc = tomllib.loads(p.read_text(encoding="utf-8"))
        doc["duration"] = min(float(doc.get("duration", 3600.0)), MAX_SHIP_DURATION)
        fleet = doc.setdefault("fleet", {})
        if fleet.get("agents", 0) > 100:
            fleet["agents"] = 100
        tasks = doc.get("tasks", {})
        if tasks.get("trace") in SHIPPED_TRACES:  # a packaged trace, by name: its first rows
            tasks["trace"] = f"data/{tasks['trace']}.csv"  # in the case's folder (mutable)
        bases[p.stem] = doc
    # a voxel trace and a voxel start file (no shipped scenario has them)
    vt = tomllib.loads((SCENARIOS / "paper_dynamic.toml").read_text(encoding="utf-8"))
    vt["duration"] = 300.0
    vt["tasks"] = {"source": "trace", "trace": "data/voxel_trace.csv", "max_wait": 120.0}
    vt.pop("sweep", None)
    vt["fleet"]["start"] = "data/voxel_fleet.csv"
    vt["fleet"]["agents"] = 4
    bases["voxel_trace"] = vt
    return bases


VOXEL_TRACE = "t,x,y,z,dest_x,dest_y,dest_z,max_wait\n" + "".join(
    f"{i * 3.5},{1.5 + i % 40},{2.5 + (i * 7) % 40},0.5,{10.5 + i % 30},{20.5},0.5,\n"
    for i in range(30))
def shipped_heads(rows: int = 40) -> dict[str, str]:
    """The header and first ``rows`` rows of each trace shipped with the package."""
    out = {}
    for name in SHIPPED_TRACES:
        with shipped_trace(name).open(encoding="utf-8") as fh:
            out[name] = "".join(line for _, line in zip(range(rows + 1), fh))
    return out


VOXEL_FLEET = "vehicle_id,x,y,z\n" + "".join(f"{i},{0.5 + i},{0.5},0.5\n" for i in range(6))

BAD_NUMBERS = [0, -1, -1.5, 0.0, 1e300, -1e300, 10**30, 2**63, 2**64, -(2**63), 1e-300,
               float("nan"), float("inf"), float("-inf"), 1e9, 1e-9, 7, 0.5, 3, 100000]
BAD_VALUES = ["", "ten", "../../etc", True, False, [], [1, 2], ["a"], {}, {"x": 1},
              [[1, [2, [3]]]], "\u00e9\u00e8", "x" * 300]
PLANNER_PARAMS = [("rstar", {"w": 0.5}), ("rstar", {"w": 2.0}), ("rrt_star", {"max_iterations": 0}),
                  ("rrt_star", {"seed": -1}), ("rrt_star", {"seed": 3}), ("reservation",
                                                                        {"retry_after": 0}),
                  ("astar", {"bogus": 1}), ("reservation", {"max_expansions": -5}),
                  ("rstar", {"delta": 0}), ("dijkstra", {}), ("astar", {}),
                  ("rrt_star", {"goal_bias": 2.0}), ("nosuch", {})]
ALLOCATOR_PARAMS = [("auction", {"bundle_size": 0}), ("auction", {"bundle_size": 2}),
                    ("auction", {"time_scale": -1}), ("magnnet", {"variant": "nope"}),
                    ("magnnet", {"checkpoint": "notes.txt"}), ("magnnet", {"checkpoint": 3}),
                    ("magnnet", {"checkpoint": "MATCH"}), ("magnnet", {"checkpoint": "PAPER"}),
                    ("magnnet", {"confidence": 2}), ("magnnet", {"patience": -1}),
                    ("hungarian", {"x": 1}), ("random", {}), ("greedy", {}), ("fcfs", {}),
                    ("local_hungarian", {"view": "all"}), ("nosuch", {})]
CHECKPOINTS = ROOT / "allocators" / "magnnet" / "checkpoints"


def _leaves(doc, prefix=()):
    for k, v in doc.items():
        if isinstance(v, dict):
            yield from _leaves(v, prefix + (k,))
        yield prefix + (k,), v


def _sec(doc: dict, name: str) -> dict:
    """The section ``name`` of ``doc`` as a table (a scalar put there by a mutation goes)."""
    if not isinstance(doc.get(name), dict):
        doc[name] = {}
    return doc[name]


def _table(doc, path):
    for k in path[:-1]:
        doc = doc[k]
    return doc


def mutate_doc(rng: random.Random, doc: dict, data: Path) -> str:
    """Change ``doc`` in place (one to three mutations); return their names."""
    names = []
    for _ in range(rng.choice((1, 1, 1, 2, 3))):
        leaves = list(_leaves(doc))
        kind = rng.choice(["number", "number", "value", "delete", "delete", "unknown", "swap",
                           "rename", "scalar_section", "source", "plugin", "plugin", "network",
                           "sweep", "deep", "world", "name"])
        names.append(kind)
        if kind in ("number", "value", "delete", "deep") and leaves:
            path, _ = rng.choice(leaves)
            table = _table(doc, path)
            if kind == "number":
                table[path[-1]] = rng.choice(BAD_NUMBERS)
            elif kind == "value":
                table[path[-1]] = rng.choice(BAD_VALUES)
            elif kind == "deep":
                table[path[-1]] = Deep(rng.choice((50, 900, 100_000)))
            else:
                del table[path[-1]]
        elif kind == "unknown":
            tables = [doc] + [v for _, v in _leaves(doc) if isinstance(v, dict)]
            rng.choice(tables)[rng.choice(["agentz", "sped", "extra", "Size", "x"])] = 1
        elif kind == "swap":
            secs = [k for k, v in doc.items() if isinstance(v, dict)]
            if len(secs) >= 2:
                a, b = rng.sample(secs, 2)
                doc[a], doc[b] = doc[b], doc[a]
        elif kind == "rename":
            secs = [k for k, v in doc.items() if isinstance(v, dict)]
            if secs:
                k = rng.choice(secs)
                doc[rng.choice(["fleets", "task", "World", "dispatcher"])] = doc.pop(k)
        elif kind == "scalar_section":
            doc[rng.choice(["world", "fleet", "tasks", "dispatch", "sweep", "comms"])] = \
                rng.choice([3, "x", [1, 2]])
        elif kind == "source":
            t = _sec(doc, "tasks")
            t["source"] = rng.choice(["static", "periodic", "poisson", "trace", "burst"])
            for k in ("interval", "rate", "count", "max_active", "trace"):
                if rng.random() < 0.4:
                    t[k] = rng.choice(BAD_NUMBERS + ["data/nothing.csv",
                                                     "data/manhattan_trips.csv"])
                elif rng.random() < 0.3:
                    t.pop(k, None)
        elif kind == "plugin":
            d = _sec(doc, "dispatch")
            if rng.random() < 0.5:
                name, params = rng.choice(PLANNER_PARAMS)
                d["planner"], d["planner_params"] = name, dict(params)
            else:
                name, params = rng.choice(ALLOCATOR_PARAMS)
                params = {k: {"MATCH": str(CHECKPOINTS / "match.pt"),
                              "PAPER": str(CHECKPOINTS / "paper_n4.pt"),
                              "notes.txt": str(data / "notes.txt")}.get(v, v)
                          if isinstance(v, str) else v for k, v in params.items()}
                d["allocator"], d["allocator_params"] = name, params
                _sec(doc, "sweep").pop("allocator", None)
        elif kind == "network":
            w = _sec(doc, "world")
            w["network"] = rng.choice(["manhattan", "chicago", "nowhere.graphml", "x.tntp",
                                       "data/notes.txt", 5])
            if rng.random() < 0.5:
                w["blocks"] = rng.choice([[2, 2], [1, 5], [100000, 100000], [3], "x"])
        elif kind == "sweep":
            s = _sec(doc, "sweep")
            k = rng.choice(["seed", "agents", "allocator", "planner"])
            s[k] = rng.choice([list(range(rng.choice((2, 20000)))), [2**63], [-1], ["greedy"],
                               [0.5], "x", [], [1, "a"]])
        elif kind == "world":
            w = _sec(doc, "world")
            if rng.random() < 0.5:
                w["cell"] = rng.choice([1e-300, 1e-3, 0.01, 0.3, 2.0, 5e-324])
            else:
                w["size"] = rng.choice([[50, 50], [1e9, 1e9, 1e9], [10000, 10000, 100],
                                        [0, 5, 5], [2, 2, 2], [50, 50, 30]])
        elif kind == "name":
            doc["name"] = rng.choice(["../../escape", "/abs/olute", "a b", "\u00e9t\u00e9",
                                      ".", "..", "ok"])
    return "+".join(names)


def mutate_text(rng: random.Random, text: str) -> tuple[bytes, str]:
    kind = rng.choice(["truncate", "truncate", "utf16", "utf32", "latin1", "bytes", "nul",
                       "dup_line", "drop_line", "deep", "junk", "empty", "bom8"])
    if kind == "truncate":
        return text[: rng.randrange(max(1, len(text)))].encode(), kind
    if kind == "utf16":
        return text.encode(rng.choice(["utf-16", "utf-16-le", "utf-16-be"])), kind
    if kind == "utf32":
        return text.encode("utf-32"), kind
    if kind == "latin1":
        return ("# caf\u00e9\n" + text).encode("latin-1", "replace"), kind
    if kind == "bytes":
        b = bytearray(text.encode())
        for _ in range(rng.randint(1, 5)):
            b.insert(rng.randrange(len(b) + 1), rng.randrange(256))
        return bytes(b), kind
    if kind == "nul":
        return text.replace("\n", "\n\x00", 1).encode(), kind
    if kind == "dup_line":
        lines = text.splitlines(True)
        i = rng.randrange(len(lines))
        return "".join(lines[: i + 1] + [lines[i]] + lines[i + 1:]).encode(), kind
    if kind == "drop_line":
        lines = text.splitlines(True)
        del lines[rng.randrange(len(lines))]
        return "".join(lines).encode(), kind
    if kind == "deep":
        d = rng.choice((1000, 100_000))
        return (text + f"\nzz = {'[' * d}{']' * d}\n").encode(), kind
    if kind == "junk":
        return bytes(rng.randrange(256) for _ in range(rng.randint(1, 400))), kind
    if kind == "empty":
        return b"", kind
    return b"\xef\xbb\xbf" + text.encode(), kind


def mutate_csv(rng: random.Random, text: str) -> tuple[bytes, str]:
    lines = text.splitlines()
    header, rows = lines[0].split(","), [r.split(",") for r in lines[1:]]
    kind = rng.choice(["cell", "cell", "cell", "drop_col", "rename_col", "extra_col", "empty",
                       "header_only", "truncate", "utf16", "junk", "dup_row", "semicolon",
                       "short_row"])
    if kind == "cell" and rows:
        r = rng.choice(rows)
        r[rng.randrange(len(r))] = rng.choice(["", "x", "nan", "inf", "-inf", "-1", "1e300",
                                               "-5", "0", "99999999", "1.5", "1e20",
                                               "9223372036854775808", "0x10"])
    elif kind == "drop_col":
        j = rng.randrange(len(header))
        header = header[:j] + header[j + 1:]
        rows = [r[:j] + r[j + 1:] for r in rows]
    elif kind == "rename_col":
        header[rng.randrange(len(header))] = rng.choice(["T", "node_id", "xx", ""])
    elif kind == "extra_col":
        header.append("extra")
        rows = [r + ["1"] for r in rows]
    elif kind == "empty":
        return b"", kind
    elif kind == "header_only":
        rows = []
    elif kind == "truncate":
        return text[: rng.randrange(max(1, len(text)))].encode(), kind
    elif kind == "utf16":
        return text.encode("utf-16"), kind
    elif kind == "junk":
        return bytes(rng.randrange(256) for _ in range(rng.randint(1, 300))), kind
    elif kind == "dup_row" and rows:
        rows.append(list(rows[0]))
    elif kind == "semicolon":
        return text.replace(",", ";").encode(), kind
    elif kind == "short_row" and rows:
        rows[rng.randrange(len(rows))] = rows[0][:1]
    out = "\n".join([",".join(header)] + [",".join(r) for r in rows]) + "\n"
    return out.encode(), kind


def generate(root: Path, n: int = N_FILES, seed: int = SEED) -> list[Case]:
    """Write ``n`` mutated cases under ``root`` (each in its own folder, with the data files
    its scenario names) and return them."""
    rng = random.Random(seed)
    bases = _bases()
    names = sorted(bases)
    cases = []
    for i in range(n):
        d = root / f"case{i:04d}"
        data = d / "data"
        data.mkdir(parents=True)
        for f in (SCENARIOS / "data").glob("*.csv"):
            shutil.copy(f, data / f.name)
        (data / "voxel_trace.csv").write_text(VOXEL_TRACE, encoding="utf-8")
        (data / "voxel_fleet.csv").write_text(VOXEL_FLEET, encoding="utf-8")
        for name, text in shipped_heads().items():
            (data / f"{name}.csv").write_text(text, encoding="utf-8")
        (data / "notes.txt").write_text("not a checkpoint\n", encoding="utf-8")
        base = rng.choice(names)
        doc = json.loads(json.dumps(bases[base]))  # a deep copy
        path = d / f"{base}.toml"
        r = rng.random()
        if r < 0.55:
            mutation = mutate_doc(rng, doc, data)
            path.write_text(dumps(doc), encoding="utf-8")
        elif r < 0.75:
            raw, mutation = mutate_text(rng, dumps(doc))
            path.write_bytes(raw)
        else:
            # a trace or start file of a base that names one
            path.write_text(dumps(doc), encoding="utf-8")
            files = [v for k, v in (("trace", doc.get("tasks", {}).get("trace")),
                                    ("start", doc.get("fleet", {}).get("start"))) if v]
            if not files:
                base = rng.choice(["manhattan", "voxel_trace"])
                doc = json.loads(json.dumps(bases[base]))
                path.unlink()
                path = d / f"{base}.toml"
                path.write_text(dumps(doc), encoding="utf-8")
                files = [doc["tasks"]["trace"], doc["fleet"]["start"]]
            target = d / rng.choice(files)
            raw, kind = mutate_csv(rng, target.read_text(encoding="utf-8"))
            target.write_bytes(raw)
            mutation = f"csv:{target.name}:{kind}"
        cases.append(Case(i, path, f"{base}:{mutation}"))
    return cases


# ----------------------------------------------------------------------------- validating


def validate_case(case: Case) -> None:
    """``dispatch validate`` in this process: ok (0), one error line (2), or a crash (any other
    exception, or an error that is not one line)."""
    out, err = io.StringIO(), io.StringIO()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = cli.main(["validate", str(case.path)])
    except BaseException as e:  # noqa: BLE001 - what the test is looking for
        case.outcome, case.message = "crash", f"{type(e).__name__}: {e}"[:500]
        return
    text = err.getvalue().strip()
    if code == 0:
        case.outcome = "ok"
    elif code == 2 and len(text.splitlines()) == 1 and text.startswith("error:"):
        case.outcome, case.message = "error", text
    else:
        case.outcome, case.message = "crash", f"exit {code}: {text[:500]}"


def first_run_overrides(case: Case) -> list[str]:
    from dispatch.scenario.load import load_scenario

    spec = load_scenario(case.path).runs()[0]
    return ["--allocator", spec.allocator, "--planner", spec.planner, "--agents",
            str(spec.agents), "--seed", str(spec.seed)]


@pytest.fixture(scope="module")
def fuzzed(tmp_path_factory):
    root = tmp_path_factory.mktemp("fuzz")
    started = time.perf_counter()
    cases = generate(root)
    for case in cases:
        validate_case(case)
        if case.outcome == "ok":
            case.overrides = first_run_overrides(case)
    return cases, time.perf_counter() - started


def test_fuzz_validate_gives_ok_or_one_line(fuzzed):
    cases, seconds = fuzzed
    counts = Counter(c.outcome for c in cases)
    print(f"\nfuzz: {len(cases)} files, {counts['error']} clear errors, {counts['ok']} ok, "
          f"{counts['crash']} crashes in {seconds:.1f} s")
    crashes = [f"{c.path.name} ({c.mutation}): {c.message}" for c in cases
               if c.outcome == "crash"]
    assert not crashes, "\n".join(crashes[:20])
    assert len(cases) >= 1000
    assert counts["error"] >= 300 and counts["ok"] >= 100  # the mix stays a mix
    kinds = Counter(c.mutation.split(":")[1].split("+")[0] for c in cases)
    assert kinds["csv"] >= 100


def test_generator_is_seeded(tmp_path):
    a = generate(tmp_path / "a", n=40)
    b = generate(tmp_path / "b", n=40)
    assert [c.mutation for c in a] == [c.mutation for c in b]
    assert all(x.path.read_bytes() == y.path.read_bytes() for x, y in zip(a, b))


# ----------------------------------------------------------------------------- running (slow)


def _limit_memory() -> None:  # in the child, before exec
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (RUN_ADDRESS_BYTES, RUN_ADDRESS_BYTES))
    resource.setrlimit(resource.RLIMIT_CPU, (RUN_CPU_S, RUN_CPU_S + 5))


def run_case(case: Case, out: Path) -> tuple[str, str]:
    cmd = [sys.executable, "-m", "dispatch.run.cli", "run", str(case.path), "--out", str(out),
           *case.overrides]
    env = {**os.environ, "COLUMNS": "400", "NO_COLOR": "1", "TERM": "dumb",
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    with open(out.parent / f"{out.name}.stdout", "w+") as so, \
            open(out.parent / f"{out.name}.stderr", "w+") as se:
        proc = subprocess.Popen(cmd, stdout=so, stderr=se, text=True, env=env,
                                cwd=case.path.parent, preexec_fn=_limit_memory)
        started = time.monotonic()
        while True:  # wait4: the child's own peak resident memory (not the other workers')
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                break
            if time.monotonic() - started > RUN_TIMEOUT_S:
                proc.kill()
                os.wait4(proc.pid, 0)
                return "hang", ""
            time.sleep(0.05)
        proc.returncode = os.waitstatus_to_exitcode(status)
        so.seek(0)
        se.seek(0)
        stdout, stderr = so.read(), se.read()
    if proc.returncode in (-signal.SIGXCPU, -signal.SIGKILL):  # past the CPU limit
        return "hang", ""
    if usage.ru_maxrss * 1024 > RUN_MEMORY_BYTES:  # (ru_maxrss: KiB on Linux)
        return "blow-up", f"{usage.ru_maxrss / 2**20:.2f} GiB resident"
    text = stdout + stderr
    if "Traceback" in text:
        return "traceback", text[-1500:]
    if proc.returncode == 0:
        return "run", ""
    if proc.returncode == 2 and len(stderr.strip().splitlines()) == 1:
        return "error", stderr.strip()
    return "other", f"exit {proc.returncode}: {text[-800:]}"


@pytest.mark.slow
def test_fuzz_runs_no_traceback_no_hang(fuzzed, tmp_path):
    cases, _ = fuzzed
    ok = [c for c in cases if c.outcome == "ok"]
    with ThreadPoolExecutor(max(1, (os.cpu_count() or 2))) as pool:
        results = list(pool.map(lambda c: run_case(c, tmp_path / f"out{c.index}"), ok))
    counts = Counter(r for r, _ in results)
    print(f"\nfuzz runs: {len(ok)} files that validate: {counts['run']} ran, "
          f"{counts['error']} one-line errors, {counts['traceback']} tracebacks, "
          f"{counts['hang']} hangs (> {RUN_CPU_S} CPU s), {counts['blow-up']} blow-ups "
          f"(> {RUN_MEMORY_BYTES / 2**30:.0f} GiB resident), {counts['other']} other")
    bad = [f"{c.path} ({c.mutation}) {c.overrides}: {r}: {m}"
           for c, (r, m) in zip(ok, results) if r in ("traceback", "hang", "blow-up", "other")]
    assert not bad, "\n\n".join(bad[:10])

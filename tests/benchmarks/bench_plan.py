"""CPU and wall time of `gmwm plan`, the whole command, against a same-run reference.

Each command runs in a fresh interpreter, ``--reps`` times: as ``python -m engine.cli plan ...``
and through the installed entry point (the ``gmwm`` script beside the interpreter, which
imports ``engine.cli`` from this tree through ``PYTHONPATH``). Its CPU time (user + sys of
the child, ``os.wait4``) and its wall time are the best (least) of the runs, the ones least
disturbed by the machine's load; the commands run in turn, one run of each per round. The
reference is a fresh interpreter that imports numpy (``python -c "import numpy"``): a fixed
cost outside the project, so the ratio is comparable between machines and loads. A last
column splits off what the command spends after its imports: the same plan timed with
``time.process_time`` in a child that imported what the command imports first.

Examples (docs/planning.md): the WN+RW datasheet example of the guide, and a consumer MEMS
gyro ``GM+WN+RW`` with three targets (N, K, B). ``--tree DIR`` adds the same commands run on
another checkout (e.g. the main tree before a change), in the same run. Byte code is written
and used as an installed package's is (``PYTHONDONTWRITEBYTECODE`` is dropped for the
children; ``--pycache DIR`` keeps it out of the trees, default a directory under /tmp).

Usage::

    nice python tests/benchmarks/bench_plan.py [--reps 5] [--tree /path/to/old/checkout]
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

EXAMPLES = {
    "WN+RW, 2 targets": [
        "--datasheet",
        "arw=0.15 deg/sqrt(h), rrw=2 deg/h/sqrt(h)",
        "--fs",
        "100",
        "--units",
        "deg/s",
        "--target",
        "K within 10 %, arw within 1 %",
        "--hours",
        "0.5,1,2,10",
    ],
    "GM+WN+RW, 3 targets": [
        "--model",
        "GM(beta=0.05, sigma2_gm=4e-6)+WN(sigma2=2.5e-5)+RW(gamma2=1e-10)",
        "--fs",
        "100",
        "--units",
        "rad/s",
        "--target",
        "N within 1 %, K within 30 %, B within 30 %",
    ],
}

_AFTER_IMPORTS = """
import sys, time
from engine.cli import main
import engine.cli.common, engine.cli.plan, engine.fit.ieee, engine.inference.planning
t = time.process_time()
main(["plan", *sys.argv[1:]])
print(f"@@{time.process_time() - t}", file=sys.stderr)
"""


def _env(tree: Path, pycache: Path) -> dict[str, str]:
    env = {**os.environ, "PYTHONPATH": str(tree), "PYTHONPYCACHEPREFIX": str(pycache)}
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def child_times(argv: list[str], tree: Path, pycache: Path) -> tuple[float, float, str]:
    """CPU seconds (user + sys) and wall seconds of one child process, and its stderr."""
    t0 = time.perf_counter()
    p = subprocess.Popen(
        argv,
        env=_env(tree, pycache),
        cwd=tree,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    err = p.stderr.read() if p.stderr else ""
    _, status, ru = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t0
    p.returncode = os.waitstatus_to_exitcode(status)
    if p.returncode != 0:
        raise SystemExit(f"{argv} failed ({p.returncode}): {err.strip()[-300:]}")
    return ru.ru_utime + ru.ru_stime, wall, err


def after_imports(args: list[str], tree: Path, pycache: Path, reps: int) -> float:
    vals = []
    for _ in range(reps):
        _, _, err = child_times([sys.executable, "-c", _AFTER_IMPORTS, *args], tree, pycache)
        vals.append(float(err.rsplit("@@", 1)[1].split()[0]))
    return min(vals)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--tree", type=Path, help="another checkout to time the same commands on")
    ap.add_argument("--pycache", type=Path, default=Path("/tmp/bench_plan_pycache"))
    a = ap.parse_args()
    trees = [("this tree", ROOT)] + ([("--tree", a.tree.resolve())] if a.tree else [])
    # the installed entry point: the gmwm script beside this interpreter (not a pyenv shim,
    # which runs a shell and pyenv first: about 0.1 s of CPU of its own)
    script = Path(sys.executable).with_name("gmwm")
    launchers = {"python -m engine.cli": [sys.executable, "-m", "engine.cli"]}
    if script.exists():
        launchers["gmwm"] = [str(script)]
    # every command once per round, in turn, so that a change of the machine's load reaches
    # all of them alike; the best of the rounds is kept
    cmds: dict[tuple[str, str, str], tuple[list[str], Path]] = {
        ("reference", "", ""): ([sys.executable, "-c", "import numpy"], ROOT),
    }
    for label, tree in trees:
        cmds["gmwm --help", "python -m engine.cli", label] = (
            [sys.executable, "-m", "engine.cli", "--help"],
            tree,
        )
    for name, args in EXAMPLES.items():
        for how, launcher in launchers.items():
            for label, tree in trees:
                cmds[name, how, label] = ([*launcher, "plan", *args], tree)
    best = {k: (math.inf, math.inf) for k in cmds}
    for _ in range(a.reps):
        for key, (argv, tree) in cmds.items():
            cpu, wall, _ = child_times(argv, tree, a.pycache)
            best[key] = (min(best[key][0], cpu), min(best[key][1], wall))
    ref_cpu, ref_wall = best["reference", "", ""]
    print(
        f"reference (python -c 'import numpy'): {ref_cpu:.3f} s of CPU, {ref_wall:.3f} s wall, "
        f"best of {a.reps}\n"
    )
    print(
        "| command | run as | tree | CPU | wall | CPU / reference CPU | plan after imports (CPU) |"
    )
    print("|---|---|---|---|---|---|---|")
    for (name, how, label), (cpu, wall) in best.items():
        if name == "reference":
            continue
        args = EXAMPLES.get(name)
        inner = "-"
        if args and how == "python -m engine.cli":
            inner = f"{after_imports(args, cmds[name, how, label][1], a.pycache, a.reps):.3f} s"
        print(
            f"| {name} | {how} | {label} | {cpu:.3f} s | {wall:.3f} s | {cpu / ref_cpu:.2f} "
            f"| {inner} |"
        )


if __name__ == "__main__":
    main()

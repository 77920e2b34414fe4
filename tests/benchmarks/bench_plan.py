"""CPU time of `gmwm plan`, the whole command, against a reference measured in the same run.

Each command runs in a fresh interpreter (``python -m engine.cli plan ...``), ``--reps`` times;
its CPU time (user + sys of the child, ``os.wait4``) is the best (least) of the runs, the
one least disturbed by the machine's load; the commands run in turn, one run of each per round. The
reference is a fresh interpreter that imports numpy (``python -c "import numpy"``): a fixed
cost outside the project, so the ratio is comparable between machines and loads. A second
column splits off what the command spends after its imports: the same plan timed with
``time.process_time`` in a child that imported what the command imports first.

Examples (docs/planning.md): the WN+RW datasheet example of the guide, and a consumer MEMS
gyro ``GM+WN+RW`` with three targets (N, K, B). ``--tree DIR`` adds the same commands run on
another checkout (e.g. the main tree before a change), in the same run.

Usage::

    nice python tests/benchmarks/bench_plan.py [--reps 5] [--tree /path/to/old/checkout]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
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
import engine.cli.common, engine.cli.plan, engine.fit, engine.inference, engine.inference.planning
t = time.process_time()
main(["plan", *sys.argv[1:]])
print(f"@@{time.process_time() - t}", file=sys.stderr)
"""


def child_cpu(argv: list[str], tree: Path) -> tuple[float, str]:
    """CPU seconds (user + sys) of one child process, and its stderr."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    p = subprocess.Popen(
        argv, env=env, cwd=tree, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
    )
    err = p.stderr.read() if p.stderr else ""
    _, status, ru = os.wait4(p.pid, 0)
    p.returncode = os.waitstatus_to_exitcode(status)
    if p.returncode != 0:
        raise SystemExit(f"{argv} failed ({p.returncode}): {err.strip()[-300:]}")
    return ru.ru_utime + ru.ru_stime, err


def after_imports(args: list[str], tree: Path, reps: int) -> float:
    vals = []
    for _ in range(reps):
        _, err = child_cpu([sys.executable, "-c", _AFTER_IMPORTS, *args], tree)
        vals.append(float(err.rsplit("@@", 1)[1].split()[0]))
    return min(vals)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--tree", type=Path, help="another checkout to time the same commands on")
    a = ap.parse_args()
    trees = [("this tree", ROOT)] + ([("--tree", a.tree.resolve())] if a.tree else [])
    # every command once per round, in turn, so that a change of the machine's load reaches
    # all of them alike; the best of the rounds is kept
    cmds: dict[tuple[str, str], tuple[list[str], Path]] = {
        ("reference", ""): ([sys.executable, "-c", "import numpy"], ROOT),
        ("gmwm --help", "this tree"): ([sys.executable, "-m", "engine.cli", "--help"], ROOT),
    }
    for label, tree in trees[1:]:
        cmds["gmwm --help", label] = ([sys.executable, "-m", "engine.cli", "--help"], tree)
    for name, args in EXAMPLES.items():
        for label, tree in trees:
            cmds[name, label] = ([sys.executable, "-m", "engine.cli", "plan", *args], tree)
    best = dict.fromkeys(cmds, float("inf"))
    for _ in range(a.reps):
        for key, (argv, tree) in cmds.items():
            best[key] = min(best[key], child_cpu(argv, tree)[0])
    ref = best["reference", ""]
    print(f"reference (python -c 'import numpy'): {ref:.3f} s of CPU, best of {a.reps}\n")
    print("| command | tree | whole command: CPU | ratio to reference | plan after imports |")
    print("|---|---|---|---|---|")
    for (name, label), cpu in best.items():
        if name == "reference":
            continue
        args = EXAMPLES.get(name)
        inner = f"{after_imports(args, cmds[name, label][1], a.reps):.3f} s" if args else "-"
        print(f"| {name} | {label} | {cpu:.2f} s | {cpu / ref:.2f} | {inner} |")


if __name__ == "__main__":
    main()

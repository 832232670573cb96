"""Long property-based fuzz run (a script, not a test): issue #13's "no failure signature".

Hypothesis draws inputs for six targets in turn, round after round, until the time budget
is spent: ``analyze`` on plain random arrays and on simulated discharges with random
corruption (random settings), the settings classes with junk values, the CSV reader (and
the CLI on the file), the bag reader (bags written by the package's writer, some damaged;
and the CLI), and the discrepancy workflow (small inputs). The properties are those of
``pneumatic_unload/test/fuzzcases.py``: only typed errors, every example ends within its time
bound, no
status "ok" with a non-finite or non-positive C, tau_exp or sigma.

A failing example is not shrunk (that costs time): its signature (exception type, where it
was raised in the package, the first words of its message) is counted, and the first
example of each signature is pickled to ``--out`` for a regression test. Prints a table of
examples and failures per target; exit status 1 when any failure was found.

Usage: ``.venv/bin/python bench/bench_fuzz.py [--minutes 10] [--seed S] [--targets a,b]
[--out DIR]``.
"""

from __future__ import annotations

import argparse
import hashlib
import pickle
import random
import sys
import tempfile
import time
import traceback
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

# fuzzcases
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "pneumatic_unload" / "test"))

import fuzzcases as fz
import fuzzio as fio
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import seed as hypothesis_seed
from hypothesis import strategies as st

#: Time bound of one example [s] per target (a longer one is a hang).
LIMITS = {"analyze_random": 60.0, "analyze_wild": 60.0, "settings": 10.0, "csv": 90.0,
          "bag": 90.0, "discrepancy": 180.0}
#: Examples per hypothesis round, per target [-].
ROUND = {"analyze_random": 200, "analyze_wild": 40, "settings": 300, "csv": 20, "bag": 20,
         "discrepancy": 2}


def signature(exc: BaseException) -> str:
    """Exception type, innermost package frame and the first words of the message."""
    where = "?"
    for fr in traceback.extract_tb(exc.__traceback__):
        if "pneumatic_unload" in fr.filename:
            where = f"{Path(fr.filename).name}:{fr.lineno}"
    words = " ".join(str(exc).split()[:8])
    return f"{type(exc).__name__} at {where}: {words}"


class Recorder:
    """Counts examples and failure signatures; keeps the first example of each."""

    def __init__(self, out: Path) -> None:
        self.out = out
        self.examples: dict[str, int] = {}
        self.failures: dict[str, dict[str, int]] = {}

    def run(self, target: str, body: Callable[[], None], data: Any) -> None:
        """Run one example's ``body`` under its time bound; record a failure."""
        self.examples[target] = self.examples.get(target, 0) + 1
        try:
            with fz.time_limit(LIMITS[target]):
                body()
        except Exception as exc:
            sig = signature(exc)
            per = self.failures.setdefault(target, {})
            if sig not in per:
                print(f"  [{target}] NEW {sig}", flush=True)
                self.out.mkdir(parents=True, exist_ok=True)
                name = hashlib.sha1(sig.encode()).hexdigest()[:10]
                with open(self.out / f"{target}-{name}.pkl", "wb") as f:
                    pickle.dump({"target": target, "signature": sig, "data": data,
                                 "traceback": traceback.format_exc()}, f)
            per[sig] = per.get(sig, 0) + 1


def make_targets(rec: Recorder) -> dict[str, Callable[[int, int], None]]:
    """Target name -> run(n_examples, seed)."""

    def runner(name: str, strategy: st.SearchStrategy[Any],
               body: Callable[[Any], None]) -> Callable[[int, int], None]:
        def run(n: int, seed: int) -> None:
            @settings(max_examples=n, deadline=None, database=None, phases=[Phase.generate],
                      suppress_health_check=list(HealthCheck))
            @hypothesis_seed(seed)
            @given(strategy)
            def prop(data: Any) -> None:
                rec.run(name, lambda: body(data), data)

            prop()
        return run

    def in_tmp(fn: Callable[[Path, Any], None]) -> Callable[[Any], None]:
        def body(data: Any) -> None:
            with tempfile.TemporaryDirectory(prefix="fuzz-") as d:
                fn(Path(d), data)
        return body

    return {
        "analyze_random": runner(
            "analyze_random", st.tuples(fz.random_traces(), fz.estimator_settings()),
            lambda d: fz.run_analyze(d[0][0], d[0][1], d[1])),
        "analyze_wild": runner(
            "analyze_wild", fz.wild_discharges().flatmap(
                lambda w: st.tuples(st.just(w), fz.estimator_settings(
                    near=fz.EstimatorSettings(**w[2].tank_fields())))),
            lambda d: fz.run_analyze(d[0][0], d[0][1], d[1])),
        "settings": runner("settings", fz.settings_keywords(), fz.prop_settings),
        "csv": runner("csv", fio.csv_files(),
                      in_tmp(lambda folder, d: fio.prop_csv(folder, d[0], d[1]))),
        "bag": runner("bag", fio.bag_cases(), in_tmp(fio.prop_bag)),
        "discrepancy": runner("discrepancy", fio.discrepancy_cases(),
                              lambda d: fio.prop_discrepancy(*d)),
    }


def main() -> int:
    """Run the targets round-robin for ``--minutes``; print the table; exit 1 on failures."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=10.0, help="time budget [min]")
    ap.add_argument("--seed", type=int, default=None, help="first round's seed (default: "
                    "random)")
    ap.add_argument("--targets", default=",".join(LIMITS),
                    help=f"comma-separated subset of {', '.join(LIMITS)}")
    ap.add_argument("--out", default="runs/fuzz", help="folder for failing examples")
    args = ap.parse_args()
    warnings.simplefilter("ignore")  # numpy's overflow warnings on wild input: not failures
    rec = Recorder(Path(args.out))
    targets = make_targets(rec)
    chosen = [t.strip() for t in args.targets.split(",") if t.strip()]
    unknown = set(chosen) - set(targets)
    if unknown:
        ap.error(f"unknown target(s) {sorted(unknown)}; known: {', '.join(targets)}")
    seed = args.seed if args.seed is not None else random.SystemRandom().randrange(2**32)
    print(f"bench_fuzz: {args.minutes:g} min over {', '.join(chosen)}; seed {seed}",
          flush=True)
    t0 = time.monotonic()
    end = t0 + 60.0 * args.minutes
    spent = dict.fromkeys(chosen, 0.0)
    k = 0
    while time.monotonic() < end:
        name = min(chosen, key=lambda c: spent[c])  # equal time per target
        s0 = time.monotonic()
        try:
            targets[name](ROUND[name], seed + k)
        except Exception as exc:  # the input generator itself (simulate...) failed
            rec.run(name, lambda e=exc: (_ for _ in ()).throw(e), {"seed": seed + k})
        spent[name] += time.monotonic() - s0
        k += 1
        if k % len(chosen) == 0:
            print(f"  {(time.monotonic() - t0) / 60:5.1f} min: " + ", ".join(
                f"{c} {rec.examples.get(c, 0)}" for c in chosen), flush=True)
    total = time.monotonic() - t0
    print(f"\n{'target':16s} {'examples':>9s} {'time [s]':>9s} {'failures':>9s}")
    for name in chosen:
        n_fail = sum(rec.failures.get(name, {}).values())
        print(f"{name:16s} {rec.examples.get(name, 0):9d} {spent[name]:9.0f} {n_fail:9d}")
    print(f"total: {sum(rec.examples.values())} examples in {total / 60:.1f} min")
    for name, per in rec.failures.items():
        for sig, n in sorted(per.items(), key=lambda kv: -kv[1]):
            print(f"  {name}: {n} x {sig}")
    n_sig = sum(len(p) for p in rec.failures.values())
    print(f"failure signatures: {n_sig}" + (f" (examples in {args.out})" if n_sig else ""))
    return 1 if n_sig else 0


if __name__ == "__main__":
    sys.exit(main())

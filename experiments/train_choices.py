"""Which recording and policy to default to: one training seed, 100 DART expert demos, variants side by side.

    .venv-train/bin/python -m experiments.train_choices TASK:VARIANT ... [--results DIR]

Uses `benchmarks/learning_curves.py`'s datasets (the same `--results` directory: DART demos to the horizon,
collected there once) and its training and evaluation (100 episodes on unseen seeds). A variant
changes one thing from `dart-5k` (mlp-chunk, 5000 steps): `dartstop` ends the demos 10 steps after
success, `c20` predicts 20-action chunks, `512x3` a wider, deeper MLP, `on05` observation noise
0.05, `gru` the recurrent policy (10-step windows), `gru50` with windows of the whole 50-step demo
(batches of 64 windows), `10k`/`30k` longer training, `x5` an ensemble of 5 (`--members 5`). The `-off`
variants start from Push's `auto` (`x5` with `--goal-offsets`) and change its steps (`2k` ... `20k`),
members (`x10`), chunk (`c5`), width (`512`), observation noise (`on05`), kind (`gru`), the
recording (`dart2`: DART noise 0.2), or add the demos' mirror images (`mirror`, `--mirror`).
`--seed` picks the training seed (0 by default; others are stored under their own names). One
JSON file per run (a run already done is skipped), and a line per run as it finishes.
"""

from __future__ import annotations

import argparse
import pathlib
import time
from typing import Any

from benchmarks import learning_curves as lc

PUSH_AUTO = lc.MEASURED_VARIANTS["mlp-chunk-x5-offsets"]
"""What `--policy auto` trained on Push before it took the demos' mirror images too (and 10000 steps),
where the `-off` variants start."""
VARIANTS: dict[str, tuple[str, int, dict[str, Any], dict[str, Any]]] = {
    "dart-5k": ("dart", 5000, {}, {}),
    "dart-10k": ("dart", 10000, {}, {}),
    "dart-30k": ("dart", 30000, {}, {}),
    "dartstop-5k": ("dartstop", 5000, {}, {}),
    "dart-5k-c20": ("dart", 5000, {"chunk": 20}, {}),
    "dart-5k-512x3": ("dart", 5000, {"hidden": 512, "layers": 3}, {}),
    "dart-5k-on05": ("dart", 5000, {}, {"obs_noise": 0.05}),
    "dart-5k-gru": ("dart", 5000, {"kind": "gru"}, {}),
    "dart-5k-gru50": ("dart", 5000, {"kind": "gru", "seq_len": 50}, {"batch_size": 64}),
    "dart-5k-x5": ("dart", 5000, {"members": 5}, {}),
    "dart-5k-c20-x5": ("dart", 5000, {"chunk": 20, "members": 5}, {}),
    "dart-5k-x5-off": ("dart", 5000, PUSH_AUTO, {}),
    "dart2-5k-x5-off": ("dart2", 5000, PUSH_AUTO, {}),
    "dart-2k-x5-off": ("dart", 2000, PUSH_AUTO, {}),
    "dart-3k-x5-off": ("dart", 3000, PUSH_AUTO, {}),
    "dart-5k-gru-off": ("dart", 5000, {"kind": "gru", "goal_offsets": True}, {}),
    "dart-5k-x10-off": ("dart", 5000, {**PUSH_AUTO, "members": 10}, {}),
    "dart-5k-c5-x5-off": ("dart", 5000, {**PUSH_AUTO, "chunk": 5}, {}),
    "dart-5k-512-x5-off": ("dart", 5000, {**PUSH_AUTO, "hidden": 512}, {}),
    "dart-10k-x5-off": ("dart", 10000, PUSH_AUTO, {}),
    "dart-20k-x5-off": ("dart", 20000, PUSH_AUTO, {}),
    "dart-5k-x5-off-on05": ("dart", 5000, PUSH_AUTO, {"obs_noise": 0.05}),
    "dart-5k-x5-off-mirror": ("dart", 5000, PUSH_AUTO, {"mirror": True}),
    "dart-10k-x5-off-mirror": ("dart", 10000, PUSH_AUTO, {"mirror": True}),
}
"""variant: (recording, gradient steps, policy settings, training settings)."""


def run(results: pathlib.Path, task: str, variant: str, seed: int = 0) -> dict[str, Any] | None:
    from fetch.learn import load
    from fetch.learn.evaluate import evaluate
    from fetch.learn.kinds import PolicySettings
    from fetch.learn.settings import TrainConfig, TrainPlan
    from fetch.learn.train import train

    name = f"{task}__{variant}" + (f"__s{seed}" if seed else "")
    target = results / "choices" / f"{name}.json"
    if target.exists():
        return None
    recording, steps, net, extra = VARIANTS[variant]
    data = lc.collected(results, task, recording, 100)
    policy = PolicySettings.of(net.get("kind", "mlp-chunk"), **{k: v for k, v in net.items() if k != "kind"})
    config = TrainConfig(steps=steps, seed=seed, demos=100, **extra)
    start, cpu = time.perf_counter(), time.process_time()
    trained = train(data, results / "choices_runs" / name, TrainPlan(policy, config),
                    log=lambda _: None, show_progress=False)
    out = {"task": task, "variant": variant, "seed": seed, "train_seconds": time.perf_counter() - start,
           "train_cpu_seconds": time.process_time() - cpu, "valid_loss": trained.valid_loss,
           **evaluate(load(trained.run), lc.EPISODES).as_dict()}
    target.parent.mkdir(parents=True, exist_ok=True)
    lc.write_json(target, out)
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("runs", nargs="+", metavar="TASK:VARIANT", help=f"variants: {', '.join(VARIANTS)}")
    p.add_argument("--results", default="/tmp/gym-fetch-learning-curves", help="as learning_curves.py's")
    p.add_argument("--seed", type=int, default=0, help="training seed (default 0)")
    args = p.parse_args()
    import fetch  # noqa: F401  (registers the ids)

    for spec in args.runs:
        task, _, variant = spec.partition(":")
        if variant not in VARIANTS or task not in lc.ALL_TASKS:
            p.error(f"{spec!r}: want TASK:VARIANT, TASK one of {', '.join(lc.ALL_TASKS)}, "
                    f"VARIANT one of {', '.join(VARIANTS)}")
        out = run(pathlib.Path(args.results), task, variant, args.seed)
        if out is not None:
            print(f"{task} {variant}: {100 * out['success_rate']:.0f}% (train {out['train_cpu_seconds']:.0f} s CPU)",
                  flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

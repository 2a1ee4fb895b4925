"""Copies a training run's checkpoint into the package as a shipped trained policy
(python/accd_gym/trained/NAME/, see docs/trained-policies.md): the model without its optimizer
state (the weights are unchanged; the file is about a third of the checkpoint's size), the
VecNormalize statistics, the run's run.json (env options: residual control, history), the actor
network exported as plain arrays (network.npz, scripts/export_networks.py) and policy.json with
its metadata (tier, algorithm, seed, steps, source run) and the recorded held-out
result (per-episode capture outcomes, from a benchmark folder or a results JSON).

    python scripts/ship_policies.py --name residual_sac_hard --results bench --tier hard \
        --method residual_sac [--check 8]

``--results`` is a benchmark folder (``accd-gym benchmark --out DIR``): the run shipped is the
one the benchmark chooses for ``--method`` on ``--tier`` on the validation episodes
(:func:`accd_gym.evals.benchmark.chosen_run`: the highest validation capture rate; the held-out
episodes play no part), its training run ``DIR/runs/KEY`` (or ``--run``); the recorded held-out
outcomes are those of ``DIR/runs/KEY/result.json`` and the LQR's those of the same folder's
baseline. policy.json records the choice (validation rates of every candidate), so it can be
recomputed from the folder. ``--results`` may instead be a JSON file of the form
``{tier: {KEY: {"captured": "0101.."}, "lqr": {...}, "base_seed": ...}}`` with ``--key`` and
``--run`` naming the run (a choice made elsewhere).

``--check K`` runs the shipped policy on its first K held-out episodes and stores each one's
outcome, steps and miss distance in policy.json (tests/test_trained_policies.py compares them)
and checks the outcomes against the recorded ones. Every file is written atomically; an
existing policy of that name is replaced only with ``--replace``.

    python scripts/ship_policies.py --recheck residual_sac_hard [--check 16]

``--recheck NAME`` re-records an already shipped policy after a change that moves episodes on
purpose (a numerical scheme, the LQR's arithmetic, the resets): it evaluates the policy as shipped
(its exported network) and the LQR on the policy's tier over the recorded number of held-out
episodes, exactly as ``accd-gym evaluate --policy NAME --policy lqr --episodes 500 --num-envs 50``
does, and rewrites policy.json's held-out row and check episodes from them. Nothing else of the
policy (weights, statistics, run.json, network) changes. It also stores every episode's length
and miss distance, which

    python scripts/ship_policies.py --verify residual_sac_hard [--episodes 100]

compares to the last bit: the check that a machine, a Python or numpy version or
``ACCD_GYM_ARITHMETIC=portable`` gives the recorded episodes.
"""

from __future__ import annotations

import argparse
import io
import sys
from pathlib import Path

from accd_gym.errors import ConfigError
from accd_gym.files import read_user_json, write_bytes, write_text

ROOT = Path(__file__).resolve().parents[1]


def stripped_model(zip_bytes: bytes, algo: str) -> bytes:
    """The saved model ``zip_bytes`` with a fresh optimizer (no Adam moments): same weights, a
    smaller file; evaluating it is unchanged."""
    from stable_baselines3 import PPO, SAC

    model = {"ppo": PPO, "sac": SAC}[algo].load(io.BytesIO(zip_bytes), device="cpu")
    policy = model.policy
    lr = model.lr_schedule(1.0)
    if algo == "ppo":
        policy.optimizer = policy.optimizer_class(policy.parameters(), lr=lr, **policy.optimizer_kwargs)
    else:
        for part in (policy.actor, policy.critic):
            part.optimizer = policy.optimizer_class(part.parameters(), lr=lr, **policy.optimizer_kwargs)
    buf = io.BytesIO()
    model.save(buf)
    return buf.getvalue()


def benchmark_results(folder: Path, name: str) -> dict:
    """The ``{tier: {"base_seed", name: {"captured"}, "lqr": {"captured"}}}`` view of one run of a
    benchmark folder: its held-out outcomes and the LQR's on the same episodes."""
    from accd_gym.evals.episodes import EVAL_BASE_SEED

    path = folder / "runs" / name / "result.json"
    if not path.is_file():
        runs = sorted(p.parent.name for p in (folder / "runs").glob("*/result.json"))
        raise ConfigError(f"invalid config: --key {name!r} has no result in {str(folder)!r} (allowed: {runs})")
    doc = read_user_json(path, "benchmark result")
    tier = doc["key"]["job"]["tier"]
    as_bits = lambda xs: "".join("1" if x else "0" for x in xs)  # noqa: E731
    out = {"base_seed": EVAL_BASE_SEED, name: {"captured": as_bits(doc["result"]["episodes"]["captured"])}}
    lqr = folder / "baselines" / f"{tier}_lqr.json"
    if lqr.is_file():
        out["lqr"] = {"captured": as_bits(read_user_json(lqr, "benchmark baseline")["record"]["captured"])}
    return {tier: out}


def check_record(episodes: list) -> list[dict]:
    """The check episodes as policy.json stores them: index, outcome, steps and the miss distance
    as the float it is (JSON keeps a double's every bit), so that a re-run compares exactly."""
    return [{"index": e.index, "outcome": e.outcome, "steps": e.steps, "min_distance": float(e.min_distance)}
            for e in episodes]


def recheck(name: str, check: int) -> int:
    """Re-records shipped policy ``name``'s held-out row and check episodes with the current code
    (see the module docstring); 0 on success."""
    import json

    from accd_gym import trained
    from accd_gym.evals.episodes import EVAL_BASE_SEED, run_episodes
    from accd_gym.envs.task import HELD_OUT_WAKE_SEEDS
    from accd_gym.evals.policies import load_policy
    from accd_gym.evals.shipped import info, policy_dir

    doc = info(name)
    tier, held = doc["tier"], doc["held_out"]
    n = int(held["episodes"])
    as_bits = lambda eps: "".join("1" if e.captured else "0" for e in eps)  # noqa: E731
    policy_eps = trained.held_out_episodes(name, n, num_envs=50)
    config = {"tier": tier}
    lqr_eps = run_episodes(load_policy("lqr", config=config), n, seed=EVAL_BASE_SEED,
                           wake_seeds=list(HELD_OUT_WAKE_SEEDS[:n]), num_envs=50, config=config)
    before = (held["captures"], held.get("lqr_captures"), held["captured"])
    captured, lqr = as_bits(policy_eps), as_bits(lqr_eps)
    held.update({
        "results": "re-evaluated with the current code (scripts/ship_policies.py --recheck)",
        "base_seed": EVAL_BASE_SEED,
        "captures": captured.count("1"),
        "captured": captured,
        "lqr_captures": lqr.count("1"),
        "lqr_captured": lqr,
        # Every episode's length and miss distance (m, every bit): what --verify compares.
        "steps": [e.steps for e in policy_eps],
        "min_distance": [float(e.min_distance) for e in policy_eps],
    })
    doc.pop("check_blas_kernels", None)
    doc["check_episodes"] = check_record(policy_eps[:check])
    write_text(policy_dir(name) / "policy.json", json.dumps(doc, indent=1) + "\n")
    changed = sum(a != b for a, b in zip(captured, before[2]))
    print(f"rechecked {name}: {tier}, {held['captures']}/{n} (was {before[0]}), LQR {held['lqr_captures']}/{n} "
          f"(was {before[1]}); {changed} of {n} outcomes changed")
    return 0


def verify(name: str, episodes: int) -> int:
    """Runs shipped policy ``name``'s first ``episodes`` held-out episodes and compares each one's
    outcome, length and miss distance, to the last bit, with those recorded by ``--recheck``;
    0 when every one agrees, 1 otherwise (the differing episodes printed)."""
    import os
    import platform

    from accd_gym import arithmetic, trained
    from accd_gym.evals.shipped import info

    held = info(name)["held_out"]
    if "steps" not in held:
        raise ConfigError(f"invalid config: {name!r} has no per-episode record (run --recheck first)")
    n = min(episodes, int(held["episodes"]))
    eps = trained.held_out_episodes(name, n, num_envs=min(50, n))
    bad = [(e.index, e.captured, e.steps, float(e.min_distance)) for e in eps
           if (e.captured, e.steps, float(e.min_distance))
           != (held["captured"][e.index] == "1", held["steps"][e.index], held["min_distance"][e.index])]
    where = (f"python {platform.python_version()}, numpy {__import__('numpy').__version__}, arithmetic {arithmetic()}, "
             f"OPENBLAS_CORETYPE={os.environ.get('OPENBLAS_CORETYPE', '-')}, {platform.machine()}")
    print(f"{name}: {n - len(bad)} of {n} episodes as recorded (outcome, steps, miss distance) [{where}]")
    for index, captured, steps, distance in bad[:10]:
        print(f"  episode {index}: captured {captured}, {steps} steps, miss {distance!r}; recorded "
              f"{held['captured'][index]}, {held['steps'][index]}, {held['min_distance'][index]!r}")
    return 0 if not bad else 1


def main(argv: list[str] | None = None) -> int:
    """Ships one run's newest checkpoint (or final model) under ``--name``, or re-records a shipped
    policy (``--recheck``); 0 on success."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--recheck", metavar="NAME", help="re-record shipped policy NAME's held-out row and check "
                    "episodes with the current code (no other option but --check)")
    ap.add_argument("--verify", metavar="NAME", help="compare shipped policy NAME's first --episodes held-out "
                    "episodes with the per-episode record of --recheck, to the last bit")
    ap.add_argument("--episodes", type=int, default=500, help="episodes for --verify (default 500)")
    ap.add_argument("--name", help="the shipped policy's name (a folder name)")
    ap.add_argument("--run", help="the training run folder (run.json, checkpoints/); default with a benchmark "
                    "folder: its chosen run's")
    ap.add_argument("--results",
                    help="results JSON with {tier: {key: {captured: '0101..'}}}, or a benchmark folder")
    ap.add_argument("--key", help="the run's entry in a results JSON (e.g. residual_ppo_s2); with a benchmark "
                    "folder it must be the run chosen on the validation episodes")
    ap.add_argument("--tier", help="with a benchmark folder: the tier of the run to choose")
    ap.add_argument("--method", help="with a benchmark folder: the method (e.g. residual_sac) whose run to choose")
    ap.add_argument("--check", type=int, default=8, help="held-out episodes to run and store (default 8)")
    ap.add_argument("--replace", action="store_true", help="replace a shipped policy of that name")
    args = ap.parse_args(argv)
    if args.verify is not None:
        return verify(args.verify, args.episodes)
    if args.recheck is not None:
        if any(v is not None for v in (args.name, args.run, args.results, args.key, args.tier, args.method)) \
                or args.replace:
            ap.error("--recheck takes no other option but --check")
        return recheck(args.recheck, args.check)
    missing = [f"--{k}" for k in ("name", "results") if getattr(args, k) is None]
    if missing:
        ap.error(f"the following arguments are required: {', '.join(missing)}")

    from accd_gym.learning.training import latest_checkpoint
    from accd_gym.evals.shipped import TRAINED_DIR

    if not args.name.replace("_", "").isalnum():
        raise ConfigError(f"invalid config: --name {args.name!r} is outside the allowed range [A-Za-z0-9_]+")
    from_benchmark = Path(args.results).is_dir()
    selection = None
    if from_benchmark:
        from accd_gym.evals.benchmark import chosen_run

        if not args.tier or not args.method:
            raise ConfigError("invalid config: a benchmark folder as --results needs --tier and --method (the run is "
                              "chosen on its validation episodes)")
        selection = chosen_run(Path(args.results), args.tier, args.method)
        if args.key is not None and args.key != selection["name"]:
            raise ConfigError(f"invalid config: --key {args.key!r} is not the run chosen on the validation episodes "
                              f"({selection['name']!r}, validation rates {selection['candidates']})")
        args.key = selection["name"]
        if args.run is None:
            args.run = str(Path(args.results) / "runs" / args.key)
    elif args.key is None or args.run is None:
        raise ConfigError("invalid config: a results JSON as --results needs --key and --run")
    run = Path(args.run)
    meta = read_user_json(run / "run.json", "run summary")
    tier = meta["config"]["env"].get("tier")
    if (run / "final_model.zip").is_file():
        model_path, stats_path, steps = run / "final_model.zip", run / "vecnormalize.pkl", meta.get("timesteps")
    else:
        ckpt = latest_checkpoint(run)
        if ckpt is None:
            raise ConfigError(f"invalid config: --run {str(run)!r} has no final model and no checkpoint")
        model_path, stats_path, steps = ckpt["model"], ckpt["vecnormalize"], ckpt["steps"]
    results = benchmark_results(Path(args.results), args.key) if from_benchmark else read_user_json(args.results, "results")
    if tier not in results or args.key not in results[tier]:
        raise ConfigError(f"invalid config: --key {args.key!r} is not in {args.results!r}[{tier!r}] "
                          f"(allowed: {sorted(k for k, v in results.get(tier, {}).items() if isinstance(v, dict))})")
    captured = results[tier][args.key]["captured"]
    lqr = results[tier].get("lqr", {}).get("captured")
    out = TRAINED_DIR / args.name
    if out.exists() and not args.replace:
        raise ConfigError(f"invalid config: --name {args.name!r}: {str(out)!r} exists (pass --replace)")
    doc = {
        "name": args.name,
        "tier": tier,
        "algo": meta["algo"],
        "seed": meta["config"].get("seed"),
        "steps": int(steps),
        "total_timesteps": meta.get("total_timesteps"),
        # A benchmark run by its name (its folder is local, runs/ is not in the repository).
        "source_run": (f"accd-gym benchmark run {args.key}" if from_benchmark
                       else str(run.resolve().relative_to(ROOT)) if run.resolve().is_relative_to(ROOT) else str(run)),
        "source_checkpoint": model_path.name,
        "env": meta["config"]["env"],
        # How the run was chosen: on the benchmark's validation episodes (None: chosen elsewhere).
        "selection": None if selection is None else {
            "on": "validation episodes", "method": args.method, "chosen": selection["name"],
            "validation_rate": selection["validation_rate"], "validation_episodes": selection["validation_episodes"],
            "candidates": selection["candidates"]},
        "held_out": {
            "results": "docs/benchmark.md" if from_benchmark else args.results,
            "key": args.key,
            "episodes": len(captured),
            "base_seed": results.get(tier, {}).get("base_seed"),
            "captures": captured.count("1"),
            "captured": captured,
            "lqr_captures": lqr.count("1") if lqr else None,
            "evaluation": f"accd-gym evaluate --policy {args.name} --policy lqr --tier {tier} --episodes "
                          f"{len(captured)} --num-envs 50",
        },
    }
    write_bytes(out / "final_model.zip", stripped_model(model_path.read_bytes(), meta["algo"]))
    write_bytes(out / "vecnormalize.pkl", stats_path.read_bytes())
    write_bytes(out / "run.json", (run / "run.json").read_bytes())
    # The actor as plain arrays: what evaluates the shipped policy (no PyTorch needed).
    from export_networks import export  # scripts/ is the script's folder, on sys.path

    export(out)
    import json

    write_text(out / "policy.json", json.dumps(doc, indent=1) + "\n")
    if args.check > 0:
        from accd_gym import trained

        eps = trained.held_out_episodes(args.name, args.check)
        doc["check_episodes"] = check_record(eps)
        got = "".join("1" if e.outcome == "captured" else "0" for e in eps)
        if got != captured[: args.check]:
            print(f"warning: {args.name}: first {args.check} held-out outcomes {got} differ from the recorded "
                  f"{captured[: args.check]}", file=sys.stderr)
        write_text(out / "policy.json", json.dumps(doc, indent=1) + "\n")
    size = sum(f.stat().st_size for f in out.iterdir())
    print(f"shipped {args.name}: {tier}, {meta['algo']} seed {doc['seed']}, {doc['steps']} steps, "
          f"recorded {doc['held_out']['captures']}/{len(captured)}; {size} bytes in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

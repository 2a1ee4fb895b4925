"""Command-line entry point ``accd-gym``."""

from __future__ import annotations

import argparse
import json
import signal
import sys
from pathlib import Path
from typing import NoReturn, Optional, Sequence

from accd_gym import files as _files
from accd_gym._core import default_aero_table_json
from accd_gym.envs.task import SEED_END
from accd_gym.envs.tiers import TIERS
from accd_gym.errors import AccdError, ConfigError
from accd_gym.studies.settle import MAX_DURATION_S
from accd_gym.files import read_user_json


def _settle(args: argparse.Namespace) -> int:
    # deferred: start-up time (a command imports only what it runs)
    from accd_gym.studies import settle

    _files.writable_folder(args.out, "--out", settle.OUTPUT_FILES)
    summary = settle.run(Path(args.out), preset=args.preset, duration=args.duration, progress=not args.quiet)
    keys = ["final_depth_m", "final_trail_m", "settling_time_s", "final_attachment_tension_N"]
    print(json.dumps({k: round(summary[k], 3) for k in keys}, indent=2))
    print(f"wrote {Path(args.out) / 'settle.png'} and {Path(args.out) / 'summary.json'}")
    return 0


def _study(args: argparse.Namespace) -> int:
    # deferred: start-up time (a command imports only what it runs)
    from accd_gym.studies import runner

    out = Path(args.out)
    try:
        runner.check_scheme(args.studies, args.scheme)
    except ValueError as e:
        raise _usage(f"--scheme: {e}".replace("invalid config: ", "")) from None
    _files.writable_folder(out, "--out", runner.output_files(args.studies))
    docs = runner.run(args.studies, out, progress=not args.quiet, dpi=args.dpi, scheme=args.scheme)
    for name, doc in docs.items():
        print(f"{name}: wrote {', '.join(str(out / f) for f in doc['figures'])}, {out / (name + '.json')}, {out / (name + '.md')}")
    if len(docs) > 1:
        print(f"all tables: {out / 'summary.md'}")
    return 0


def _export_aero(args: argparse.Namespace) -> int:
    out = _files.check_output_file(args.out, "--out")
    _files.write_text(out, default_aero_table_json())
    print(f"wrote the default ACCD aerodynamic tables to {out}")
    return 0


def _train(args: argparse.Namespace) -> int:
    # deferred: start-up time (a command imports only what it runs)
    from accd_gym.learning import training

    if args.resume:
        if args.config is not None or args.timesteps is not None or args.seed is not None or args.tier:
            raise _usage("--resume continues a run with its own config; drop --config, --timesteps, --seed and --tier")
        out = Path(args.resume)
        # deferred: start-up time (a command imports only what it runs)
        from accd_gym.learning.rllib import is_rllib_run

        if is_rllib_run(out):
            raise _usage(f"--resume {str(out)!r}: resuming an RLlib run is not supported; its checkpoints/ restore with "
                         "ray.rllib.algorithms.Algorithm.from_checkpoint")
        meta = training.resume(out, progress=not args.quiet,
                               report=lambda line: print(f"accd-gym: {line}", file=sys.stderr, flush=True))
    else:
        if args.out is None:
            raise _usage("train needs --out RUN (or --resume RUN)")
        out = Path(args.out)
        if _is_rllib_config(args.config):
            # deferred: start-up time (a command imports only what it runs)
            from accd_gym.learning import rllib

            meta = rllib.train(rllib.load_config(args.config, seed=args.seed), out, timesteps=args.timesteps,
                               progress=not args.quiet)
        else:
            cfg = training.load_config(args.config or "training/ppo.json", seed=args.seed)
            if args.tier:
                cfg = training.validate_config({**cfg, "env": {"tier": args.tier, **cfg["env"]}})
            meta = training.train(cfg, out, timesteps=args.timesteps, progress=not args.quiet)
    if meta["status"] == "interrupted":
        print(f"accd-gym: training interrupted ({meta['interrupted_by']}) at {meta['timesteps']} of "
              f"{meta['config']['total_timesteps']} steps; checkpoint {meta['checkpoint']} written; "
              f"continue with: accd-gym train --resume {out}", file=sys.stderr)
        return 130
    if meta.get("trainer") == "rllib":
        print(f"trained RLlib {meta['algo'].upper()} for {meta['timesteps']} steps in {meta['wall_time_s']} s "
              f"({meta['steps_per_s']} steps/s); wrote {out / 'final_model'}, TensorBoard logs in {out / 'tb'}")
        return 0
    print(f"trained {meta['algo'].upper()} for {meta['timesteps']} steps in {meta['wall_time_s']} s "
          f"({meta['steps_per_s']} steps/s); wrote {out / 'final_model.zip'}, "
          f"{out / 'vecnormalize.pkl'}, TensorBoard logs in {out / 'tb'}")
    return 0


def _distill(args: argparse.Namespace) -> int:
    # deferred: start-up time (a command imports only what it runs)
    from accd_gym.evals.policies import load_policy
    from accd_gym.learning import distill

    def teacher(spec: str, seed: int, config: dict):
        return load_policy(spec, seed, config=config)

    def report(line: str) -> None:
        if not args.quiet:
            print(f"accd-gym distill: {line}", file=sys.stderr, flush=True)

    if args.resume:
        if args.config is not None or args.seed is not None or args.out is not None:
            raise _usage("--resume continues a run in its own folder with its own recipe; drop --config, --seed and --out")
        out = Path(args.resume)
        meta = distill.resume(out, make_teacher=teacher, report=report)
    else:
        if args.config is None or args.out is None:
            raise _usage("distill needs --config RECIPE and --out RUN (or --resume RUN)")
        out = Path(args.out)
        meta = distill.train(distill.load_recipe(args.config, seed=args.seed), out, make_teacher=teacher, report=report)
    if meta["status"] == "interrupted":
        print(f"accd-gym: distillation interrupted with {len(meta['rounds'])} complete round(s); continue with: "
              f"accd-gym distill --resume {out}", file=sys.stderr)
        return 130
    last = meta["rounds"][-1]
    print(f"distilled {meta['config']['teacher']} into a {meta['method'].upper()} student: {len(meta['rounds'])} rounds, "
          f"{meta['timesteps']} labelled steps, final train MSE {last['train_mse']:.5f}, in {meta['wall_time_s']} s; "
          f"wrote {out / 'final_model.zip'}, {out / 'vecnormalize.pkl'}")
    return 0


def _is_rllib_config(path: Optional[str]) -> bool:
    """Whether the training config file at ``path`` asks for the RLlib trainer (a file that cannot
    be read is left to the loader's error)."""
    # deferred: start-up time (a command imports only what it runs)
    from accd_gym.learning.rllib import is_rllib_config

    try:
        return path is not None and Path(path).exists() and is_rllib_config(read_user_json(path, "training config"))
    except ConfigError:
        return False


def _benchmark(args: argparse.Namespace) -> int:
    # deferred: start-up time (a command imports only what it runs)
    from accd_gym.evals import benchmark

    seeds = _seeds(args.seeds)  # before the config is read: a bad option is named first
    cfg = benchmark.load_config(args.config, quick=args.quick)
    chosen = benchmark.selection(cfg, tiers=_names(args.tiers), algos=_names(args.algos), seeds=seeds)
    docs = Path(args.docs) if args.docs else None
    command = ("accd-gym benchmark" + (f" --config {args.config}" if args.config != "training/benchmark.json" else "")
               + (" --quick" if args.quick else "") + (f" --ray {args.ray}" if args.ray else ""))
    progress = (lambda m: None) if args.quiet else (lambda m: print(m, file=sys.stderr, flush=True))
    readme = Path(args.readme) if args.readme else None
    doc = benchmark.run(cfg, args.out, ray_address=args.ray, docs=docs, command=command, progress=progress,
                        chosen=chosen, readme=readme)
    print((Path(args.out) / "benchmark.md").read_text())
    print(f"wrote {Path(args.out) / 'benchmark.json'}, benchmark.md, performance_profile.png, episodes.json"
          + (f"; {docs / 'benchmark.md'}" if docs else "") + (f"; the table of {readme}" if readme else "")
          + f" (wall time {doc['wall_time_s']:.0f} s)")
    if doc.get("interrupted"):
        print(f"accd-gym: benchmark interrupted ({doc['interrupted']}); the report covers the finished runs; "
              f"run the same command again to resume", file=sys.stderr)
        return 130
    return 0


def _names(text: Optional[str]) -> Optional[list[str]]:
    """A comma-separated option's values (None when not given)."""
    return None if text is None else [v.strip() for v in text.split(",") if v.strip()]


def _seeds(text: Optional[str]) -> Optional[list[int]]:
    """--seeds as integers in the seed range; a usage error naming a value that is not one."""
    values = _names(text)
    if values is None:
        return None
    try:
        return [_seed_value("--seeds", v) for v in values]
    except argparse.ArgumentTypeError as e:
        raise _usage(str(e)) from None


def _sweep(args: argparse.Namespace) -> int:
    # deferred: start-up time (a command imports only what it runs)
    from accd_gym.evals import sweep

    doc = sweep.run(args.config, args.out, progress=not args.quiet)
    print((Path(args.out) / "summary.md").read_text())
    print(f"wrote {Path(args.out) / 'sweep.json'}, summary.md, trial run folders in {Path(args.out) / 'trials'}")
    return 0 if not doc["failed"] else 1


class _UsageError(Exception):
    """A misuse of the command line found after parsing (exit code 2, one line)."""


def _usage(message: str) -> _UsageError:
    """A :class:`_UsageError` with ``message``."""
    return _UsageError(message)


#: The most digits an integer option is read with (Python refuses to convert longer ones).
_MAX_DIGITS = 100


def _integer(name: str, text: str, low: int, high: int) -> int:
    """``text`` as an integer in [low, high]; an ArgumentTypeError naming option ``name`` and
    quoting the value as given otherwise."""
    stripped = text.strip()
    if len(stripped) > _MAX_DIGITS or not stripped.lstrip("+-").isascii():
        raise argparse.ArgumentTypeError(f"{name} = {text[:40]!r} is not an integer in [{low}, {high}]")
    try:
        value = int(stripped)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{name} = {text!r} is not an integer") from None
    if not low <= value <= high:
        raise argparse.ArgumentTypeError(f"{name} = {text} is outside the allowed range: an integer in [{low}, {high}]")
    return value


def _count(name: str, low: int, high: int):
    """An argparse type: an integer in [low, high], with an error naming the option."""

    def parse(text: str) -> int:
        return _integer(name, text, low, high)

    return parse


def _nonnegative(name: str, high: int = 10**6):
    """An argparse type: an integer in [0, high], with an error naming the option."""
    return _count(name, 0, high)


def _positive(name: str, high: int = 10**6):
    """An argparse type: an integer in [1, high], with an error naming the option."""
    return _count(name, 1, high)


def _seed_value(name: str, text: str) -> int:
    """``text`` as a seed: an integer in the one seed range [0, 2^63)
    (:data:`accd_gym.envs.task.SEED_END`); the error quotes the value as given."""
    return _integer(name, text, 0, SEED_END - 1)


def _seed(text: str) -> int:
    """An argparse type: a seed, an integer in the seed range [0, 2^63)."""
    return _seed_value("--seed", text)


def _path(name: str):
    """An argparse type: a file or folder path: not empty and without a NUL character (which no
    file name holds), with an error naming the option."""

    def parse(text: str) -> str:
        if text == "":
            raise argparse.ArgumentTypeError(f"{name} is empty; it must name a file or folder")
        if "\0" in text:
            raise argparse.ArgumentTypeError(f"{name} = {text!r} contains a NUL character, which no file name holds")
        return text

    return parse


def _seconds(name: str, high: float):
    """An argparse type: a number of seconds in (0, high], with an error naming the option."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} = {text[:40]!r} is not a number") from None
        if not 0 < value <= high:
            raise argparse.ArgumentTypeError(f"{name} = {text[:40]} is outside the allowed range: (0, {high:g}] s")
        return value

    return parse


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (exit code 2), pointing to ``--help``."""

    def error(self, message: str):  # type: ignore[override]
        """Prints ``prog: error: message`` on one line and exits with code 2."""
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see {self.prog} --help)\n")


def _env_of(args: argparse.Namespace) -> dict:
    """The environment config overrides of --env, over the tier of --tier (if given; else, for
    shipped trained policies of one tier, theirs, with a note)."""
    env = _env_overrides(args.env)
    if getattr(args, "tier", None):
        env = {"tier": args.tier, **env}
    elif "tier" not in env:
        # deferred: start-up time (a command imports only what it runs)
        from accd_gym.trained import info, is_trained

        specs = args.policy if isinstance(getattr(args, "policy", None), list) else [getattr(args, "policy", "")]
        tiers = sorted({info(s)["tier"] for s in specs if isinstance(s, str) and is_trained(s)})
        if len(tiers) == 1:
            print(f"note: the trained policies' tier {tiers[0]!r} (--tier sets another)", file=sys.stderr)
            env = {"tier": tiers[0], **env}
    return env


def _env_overrides(text: Optional[str]) -> dict:
    """The --env JSON object (environment config overrides)."""
    if not text:
        return {}
    try:
        value = json.loads(text)
    except ValueError as e:  # not JSON, or an integer of more digits than Python converts
        raise ConfigError(f"invalid config: --env {_clip(text)!r} is not a JSON object ({_clip(str(e), 200)})") from None
    except RecursionError:
        raise ConfigError(f"invalid config: --env {_clip(text)!r} is nested too deeply to read") from None
    if not isinstance(value, dict):
        raise ConfigError(f"invalid config: --env {_clip(text)!r} is not a JSON object")
    return value


def _clip(text: str, limit: int = 80) -> str:
    """``text`` cut to ``limit`` characters for a message (an option can be megabytes long)."""
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _evaluate(args: argparse.Namespace) -> int:
    # deferred: start-up time (a command imports only what it runs)
    from accd_gym.evals import evaluation
    from accd_gym.replays import replay

    if args.ray_chunk is not None and args.ray is None:
        raise _usage("--ray-chunk sets the episodes per Ray task; it needs --ray")

    if args.validation:
        # deferred: start-up time (a command imports only what it runs)
        from accd_gym.envs.task import VALIDATION_WAKE_SEEDS
        from accd_gym.evals.episodes import VALIDATION_BASE_SEED

        if args.episodes > len(VALIDATION_WAKE_SEEDS):
            raise _usage(f"--episodes {args.episodes} is outside the allowed range 1..{len(VALIDATION_WAKE_SEEDS)} "
                         "with --validation (the validation wake seeds)")
        where = {"wake_seeds": list(VALIDATION_WAKE_SEEDS[:args.episodes]), "seed": VALIDATION_BASE_SEED}
    else:
        where = {}
    results = evaluation.evaluate(args.policy, args.episodes, args.out, **where, num_envs=args.num_envs, num_threads=args.num_threads,
                                  config=_env_of(args), progress=not args.quiet,
                                  allow_unnormalized=args.allow_unnormalized,
                                  replay_writer=replay.evaluation_replays(args.replay) if args.replay else None,
                                  ray_address=args.ray, ray_chunk=args.ray_chunk)
    for spec, doc in results["policies"].items():
        if doc.get("note"):
            print(f"note: {doc['note']}", file=sys.stderr)
    print((Path(args.out) / "summary.md").read_text())
    print(f"wrote {Path(args.out) / 'results.json'}, summary.md, trajectories.png, miss_distance_cdf.png")
    for spec, pages in results.get("replays", {}).items():
        for page in pages:
            print(f"replay of {spec} ({page['pick']}, episode {page['episode']}, {page['outcome']}): {page['html']}")
    return 0 if results["policies"] else 1


def _replay(args: argparse.Namespace) -> int:
    # deferred: start-up time (a command imports only what it runs)
    from accd_gym.replays import replay

    written = replay.run_replay(args.policy, args.episodes, args.out, seed=args.seed, config=_env_of(args),
                                num_envs=args.num_envs, num_threads=args.num_threads, video=args.video,
                                screenshot=args.screenshot, max_frames=args.max_frames,
                                allow_unnormalized=args.allow_unnormalized, progress=not args.quiet, only=args.only)
    for e in written:
        files = ", ".join(e[k] for k in ("html", "npz", "mp4", "png") if k in e)
        print(f"episode {e['episode']}: {e['outcome']} after {e['steps']} steps, miss {e['min_distance']:.3f} m: {files}")
    return 0


def _rollout(args: argparse.Namespace) -> int:
    # deferred: start-up time (a command imports only what it runs)
    from accd_gym.evals import evaluation

    config = _env_of(args)
    policy = evaluation.load_policy(args.policy, seed=args.seed, allow_unnormalized=args.allow_unnormalized, config=config)
    if getattr(policy, "note", None):
        print(f"note: {policy.note}", file=sys.stderr)
    eps = evaluation.run_episodes(policy, args.episodes, seed=args.seed, num_envs=args.num_envs, num_threads=args.num_threads,
                                  config=config, progress=not args.quiet, desc=args.policy)
    s = evaluation.summarize(eps)
    lo, hi = s["capture_rate_ci95"]
    print(f"{args.policy}: {s['captures']}/{s['episodes']} captured ({s['capture_rate']:.1%}, 95% CI {lo:.1%}-{hi:.1%}); "
          f"outcomes {s['outcomes']}; median miss distance {s['miss_distance_m']['median']:.2f} m; "
          f"mean return {s['mean_return']:.1f}")
    if args.json:
        print(json.dumps({"summary": s, "episodes": [e.metrics() for e in eps]}, indent=1))
    return 0


def _dataset(args: argparse.Namespace) -> int:
    # deferred: start-up time (a command imports only what it runs)
    from accd_gym.evals import datasets

    try:
        # deferred: minari is the optional dataset extra; checked before any episode runs
        import minari  # noqa: F401
    except ModuleNotFoundError as e:
        raise _usage(f"`accd-gym dataset` needs the dataset extra ({e}): pip install 'accd-gym[dataset]'") from None
    done = datasets.record_dataset(args.policy, args.tier, args.episodes, args.out, seed=args.seed,
                                   true_observation=args.true_observation, num_envs=args.num_envs,
                                   num_threads=args.num_threads)
    print(f"wrote Minari dataset {done['id']}: {done['episodes']} episodes, {done['steps']} steps, in {done['path']} "
          f"(load it with MINARI_DATASETS_PATH={Path(args.out).resolve()} and minari.load_dataset({done['id']!r}))")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``accd-gym`` and its subcommands."""
    parser = _Parser(prog="accd-gym", description="accd-gym: In-Air Capturing simulation tools.")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("settle", help="simulate a towed tether settling behind the aircraft and plot it")
    p.add_argument("--out", type=_path("--out"), default="runs/settle", help="output folder (default: runs/settle)")
    p.add_argument("--preset", default="table3", help="tether preset, e.g. table3 or steel-250m-24mm")
    p.add_argument("--duration", type=_seconds("--duration", MAX_DURATION_S), default=120.0,
                   help=f"simulated time in seconds, at most {MAX_DURATION_S:g} (default 120)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_settle)
    # deferred: start-up time (a command imports only what it runs)
    from accd_gym.studies.study import EXTRA_STUDIES, STUDIES

    p = sub.add_parser("study", help="run the paper's section-4 tether design studies: plots, JSON, markdown tables")
    p.add_argument("studies", nargs="+", choices=[*STUDIES, *EXTRA_STUDIES, "all"], metavar="STUDY",
                   help=f"one or more of: {', '.join(STUDIES)}, all (these), or the longer {', '.join(EXTRA_STUDIES)}")
    p.add_argument("--out", type=_path("--out"), default="runs/study", help="output folder (default: runs/study)")
    p.add_argument("--dpi", type=_count("--dpi", 10, 1200), default=90, help="resolution of the PNGs, 10 to 1200 (default 90)")
    p.add_argument("--scheme", choices=["explicit", "implicit_axial"], default="explicit",
                   help="the tether's integration scheme for fig9 and tension: explicit RK4 at each run's stable "
                        "step (default) or implicit_axial, every run at the default 0.01 s step")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_study)
    p = sub.add_parser("export-aero", help="write the default ACCD aerodynamic tables (JSON) to start your own")
    p.add_argument("--out", type=_path("--out"), default="accd-aero.json", help="output file (default: accd-aero.json)")
    p.set_defaults(func=_export_aero)
    p = sub.add_parser("train", help="train PPO or SAC on the capture task (stable-baselines3, or RLlib PPO for a config with \"trainer\": \"rllib\")")
    p.add_argument("--config", type=_path("--config"), help="training config, JSON (default: training/ppo.json)")
    p.add_argument("--out", type=_path("--out"), help="run folder: model, VecNormalize statistics, checkpoints, TensorBoard logs (one that holds no run yet; --resume continues one)")
    p.add_argument("--resume", type=_path("--resume"), metavar="RUN",
                   help="continue the interrupted run in folder RUN from its latest checkpoint to its total")
    p.add_argument("--timesteps", type=_positive("--timesteps", 10**12), help="override the config's total_timesteps")
    p.add_argument("--seed", type=_seed, help="override the config's seed")
    p.add_argument("--tier", choices=list(TIERS), help="a benchmark tier (accd_gym.envs.tiers): trained on with the config's env overrides on top")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_train)
    p = sub.add_parser("evaluate", help="evaluate policies on held-out wake seeds: JSON, plots, markdown")
    p.add_argument("--policy", action="append", required=True,
                   help="a baseline (zero, random, guidance, lqr, mpc), a shipped trained policy (accd_gym.trained) or a trained model "
                        "(run folder or .zip); repeatable")
    p.add_argument("--episodes", type=_positive("--episodes"), default=100, help="episodes per policy (default 100)")
    p.add_argument("--out", type=_path("--out"), default="runs/eval", help="output folder (default: runs/eval)")
    p.add_argument("--num-envs", type=_positive("--num-envs"), default=16, help="parallel episodes (default 16)")
    p.add_argument("--num-threads", type=_nonnegative("--num-threads"), default=0,
                   help="threads stepping the envs (default 0: one per core)")
    p.add_argument("--env", help="environment config overrides as JSON, e.g. '{\"capture_window\": 30}'")
    p.add_argument("--tier", choices=list(TIERS), help="a benchmark tier (accd_gym.envs.tiers): its config, under --env")
    p.add_argument("--allow-unnormalized", action="store_true",
                   help="evaluate a model without its vecnormalize.pkl (observations passed raw)")
    p.add_argument("--replay", type=_nonnegative("--replay"), default=0, metavar="K",
                   help="also write 3D replay pages of K episodes per policy (3: best, median, worst) to OUT/replays")
    p.add_argument("--ray", nargs="?", const="local", metavar="ADDRESS",
                   help="run the episodes as Ray tasks: 'local' (default), 'auto' or HOST:PORT of a cluster "
                        "(needs the ray extra; results identical to a local run)")
    p.add_argument("--ray-chunk", type=_positive("--ray-chunk"), help="episodes per Ray task (default: about 4 tasks per CPU)")
    p.add_argument("--validation", action="store_true",
                   help="the validation episodes (validation wake seeds, the benchmark's validation base seed) instead "
                        "of the held-out ones: for choices (a run, a hyperparameter)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_evaluate)

    p = sub.add_parser("distill", help="distil a controller into a standalone network: behaviour cloning and DAgger")
    p.add_argument("--config", type=_path("--config"), help="distillation recipe, JSON (training/distill_*.json)")
    p.add_argument("--out", type=_path("--out"), help="run folder: the student (final_model.zip, vecnormalize.pkl), "
                   "run.json, checkpoints/")
    p.add_argument("--resume", type=_path("--resume"), metavar="RUN",
                   help="continue an interrupted distillation run after its last complete round")
    p.add_argument("--seed", type=_seed, help="override the recipe's seed")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=_distill)
    p = sub.add_parser("replay", help="record episodes of a policy: .npz, a self-contained 3D replay page each, MP4")
    p.add_argument("--policy", required=True, help="a baseline (zero, random, guidance, lqr, mpc), a shipped trained policy (accd_gym.trained) or a trained model")
    p.add_argument("--episodes", type=_positive("--episodes"), default=1, help="episodes (default 1)")
    p.add_argument("--out", type=_path("--out"), default="runs/replay", help="output folder (default: runs/replay)")
    p.add_argument("--seed", type=_seed, default=None,
                   help="base seed of initial conditions and RLV motion (default: the evaluation's, 20240607)")
    p.add_argument("--num-envs", type=_positive("--num-envs"), default=16,
                   help="parallel episodes, the batch the policy sees (default 16, as evaluate: episode k is evaluate's episode k)")
    p.add_argument("--num-threads", type=_nonnegative("--num-threads"), default=0,
                   help="threads stepping the envs (default 0: one per core)")
    p.add_argument("--env", help="environment config overrides as JSON")
    p.add_argument("--tier", choices=list(TIERS), help="a benchmark tier (accd_gym.envs.tiers): its config, under --env")
    p.add_argument("--only", type=_nonnegative("--only"), action="append", metavar="K",
                   help="write only episode K of the --episodes run (repeatable; the others run unrecorded)")
    p.add_argument("--video", action="store_true", help="also write an MP4 per episode (imageio-ffmpeg)")
    p.add_argument("--screenshot", action="store_true",
                   help="also write a PNG of each page at the capture or the closest approach (headless chromium)")
    p.add_argument("--max-frames", type=_positive("--max-frames"), default=1000,
                   help="most 3D frames per page; longer recordings are decimated (default 1000)")
    p.add_argument("--allow-unnormalized", action="store_true",
                   help="run a model without its vecnormalize.pkl (observations passed raw)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_replay)
    p = sub.add_parser("sweep", help="training seeds (and a hyperparameter grid) as Ray Tune trials, each evaluated on held-out seeds")
    p.add_argument("--config", type=_path("--config"), default="training/sweep_seeds.json", help="sweep config, JSON (default: training/sweep_seeds.json)")
    p.add_argument("--out", type=_path("--out"), default="runs/sweep", help="output folder (default: runs/sweep)")
    p.add_argument("--quiet", action="store_true", help="less output from Tune")
    p.set_defaults(func=_sweep)
    p = sub.add_parser("benchmark", help="the benchmark suite: learned policies (PPO on every tier, residual PPO and SAC, behaviour cloning and DAgger on the precision and hard tiers) with several seeds, every baseline, one report")
    p.add_argument("--config", type=_path("--config"), default="training/benchmark.json", help="benchmark config, JSON (default: training/benchmark.json)")
    p.add_argument("--out", type=_path("--out"), default="runs/benchmark", help="output folder (default: runs/benchmark)")
    p.add_argument("--quick", action="store_true", help="the config's quick overrides: a few minutes, for CI")
    p.add_argument("--tiers", metavar="A,B", help="run only these tiers' jobs (the report covers every finished run)")
    p.add_argument("--algos", metavar="A,B", help="run only these algorithms' jobs")
    p.add_argument("--seeds", metavar="0,1", help="run only these seeds' jobs")
    p.add_argument("--docs", type=_path("--docs"), metavar="FOLDER", help="also write FOLDER/benchmark.md and FOLDER/figures/benchmark_profile.png")
    p.add_argument("--readme", type=_path("--readme"), metavar="FILE", help="also rewrite the results table of FILE (a README) between its benchmark-table markers")
    p.add_argument("--ray", nargs="?", const="local", metavar="ADDRESS",
                   help="run the training jobs as Ray tasks: 'local' (default), 'auto' or HOST:PORT (needs the ray extra)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=_benchmark)
    p = sub.add_parser("rollout", help="run a policy for a few episodes headless and print a summary")
    p.add_argument("--policy", required=True, help="a baseline (zero, random, guidance, lqr, mpc), a shipped trained policy (accd_gym.trained) or a trained model")
    p.add_argument("--episodes", type=_positive("--episodes"), default=8, help="episodes (default 8)")
    p.add_argument("--seed", type=_seed, default=0, help="base seed (training wake seeds are drawn from it)")
    p.add_argument("--num-envs", type=_positive("--num-envs"), default=8, help="parallel episodes (default 8)")
    p.add_argument("--num-threads", type=_nonnegative("--num-threads"), default=0,
                   help="threads stepping the envs (default 0: one per core)")
    p.add_argument("--env", help="environment config overrides as JSON")
    p.add_argument("--tier", choices=list(TIERS), help="a benchmark tier (accd_gym.envs.tiers): its config, under --env")
    p.add_argument("--allow-unnormalized", action="store_true",
                   help="run a model without its vecnormalize.pkl (observations passed raw)")
    p.add_argument("--json", action="store_true", help="also print every episode's metrics as JSON")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_rollout)
    p = sub.add_parser("dataset", help="record episodes of a policy on training wake seeds as a Minari dataset (offline RL, imitation)")
    p.add_argument("--policy", required=True, help="a baseline (lqr, guidance, ...), a shipped trained policy (accd_gym.trained) or a trained model")
    p.add_argument("--tier", required=True, choices=list(TIERS), help="the benchmark tier the episodes run on")
    p.add_argument("--episodes", type=_positive("--episodes"), default=100, help="episodes (default 100)")
    p.add_argument("--out", type=_path("--out"), default="runs/datasets",
                   help="Minari dataset root the dataset is written into (default: runs/datasets)")
    p.add_argument("--seed", type=_seed, default=0, help="base seed of the episodes' initial conditions and RLV motion (default 0)")
    p.add_argument("--true-observation", action="store_true",
                   help="also store the noise-free, delay-free observation of every step in infos['true_obs']")
    p.add_argument("--num-envs", type=_positive("--num-envs"), default=16, help="parallel episodes (default 16)")
    p.add_argument("--num-threads", type=_nonnegative("--num-threads"), default=0,
                   help="threads stepping the envs (default 0: one per core)")
    p.set_defaults(func=_dataset)
    return parser


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Runs ``accd-gym`` with ``argv`` (default: the process arguments); returns the exit code."""
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (AccdError, _UsageError) as e:
        print(f"accd-gym: error: {_one_line(e)}", file=sys.stderr)
        return 2
    except ModuleNotFoundError as e:
        if e.name in ("plotly", "imageio_ffmpeg"):
            print(f"accd-gym: error: `accd-gym {args.command}` needs the replay extra ({e}): pip install 'accd-gym[replay]'",
                  file=sys.stderr)
            return 2
        if e.name == "ray" or (e.name or "").startswith("ray."):
            print(f"accd-gym: error: `accd-gym {args.command}` with Ray needs the ray extra ({e}): pip install 'accd-gym[ray]'",
                  file=sys.stderr)
            return 2
        if e.name not in ("stable_baselines3", "torch", "tensorboard", "rich"):
            raise
        print(f"accd-gym: error: `accd-gym {args.command}` needs the sb3 extra ({e}): pip install 'accd-gym[sb3]'", file=sys.stderr)
        return 2
    except OSError as e:  # a file or folder the user named cannot be read or written
        where = f" {e.filename!r}" if e.filename else ""
        print(f"accd-gym: error: cannot access{where}: {e.strerror or e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("accd-gym: interrupted", file=sys.stderr)
        return 130


def run() -> NoReturn:
    """The ``accd-gym`` executable (and ``python -m accd_gym``): :func:`main` on the process
    arguments, then exit with its code.

    Once the command has returned, its files are written and its exit code is decided, so Ctrl+C
    is ignored from then on: an interrupt arriving while the interpreter shuts down would otherwise
    surface as a traceback from some library's exit handler (PyTorch registers several) and turn a
    clean exit into a crash report. An interrupt between the command's end and this point exits
    with 130, as one during the command does.
    """
    try:
        code = main()
    except KeyboardInterrupt:
        print("accd-gym: interrupted", file=sys.stderr)
        code = 130
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    sys.exit(code)


def _one_line(error: Exception) -> str:
    """An exception's message on one line."""
    return " ".join(str(error).split())


if __name__ == "__main__":
    run()

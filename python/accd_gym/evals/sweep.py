"""Training-seed sweeps and hyperparameter grids as Ray Tune trials (``pip install 'accd-gym[ray]'``).

``accd-gym sweep --config training/sweep_seeds.json --out runs/sweep`` calls :func:`run`: one
Tune trial per training seed (times each point of an optional grid), each training with either
trainer (the ``train_config`` decides: a stable-baselines3 config, or an RLlib one with
``"trainer": "rllib"``), then evaluating its final model on the first ``episodes`` held-out
wake seeds (:func:`accd_gym.evals.evaluation.run_episodes`, the episodes every trial shares). The
same command runs on one machine (``"ray_address": "local"``) and on a cluster (``"auto"`` or
``HOST:PORT``): Tune places the trials.

Sweep config (JSON object; every key but ``train_config`` optional):

==================== ==============================================================================
key                  meaning
==================== ==============================================================================
train_config         path of the training config every trial starts from
seeds                training seeds (default ``[0, 1, 2, 3, 4]``)
grid                 ``{"dotted.key": [values...]}`` of the training config, e.g.
                     ``{"algo_kwargs.learning_rate": [0.0003, 0.001]}`` (default none)
timesteps            total steps per trial (default: the training config's)
episodes             evaluation episodes per trial (default 200)
eval_split           which episodes evaluate the trials: ``"held_out"`` (default: the first
                     ``episodes`` held-out wake seeds, the benchmark's episodes) or
                     ``"validation"`` (wake seeds of the training set,
                     :data:`accd_gym.envs.task.VALIDATION_WAKE_SEEDS`, from base seed
                     :data:`accd_gym.evals.episodes.VALIDATION_BASE_SEED`): tune on
                     ``validation``, so that the held-out episodes stay unseen until the benchmark
num_envs             evaluation batch size (default 16)
eval_env             env overrides of the evaluation (default: the training config's ``env``)
baselines            built-in baselines (``zero``, ``random``, ``guidance``, ``lqr``) evaluated once on
                     the same episodes, on the evaluation's env without the agent's options
                     (``residual``, ``history``), as the reference the trials are read against
                     (default none)
cpus_per_trial       CPUs Tune reserves per trial, also the threads stepping its envs (default 1)
max_concurrent_trials  at most this many trials at once (default 0: as the CPUs allow)
ray_address          ``"local"`` (default), ``"auto"`` or ``HOST:PORT``
==================== ==============================================================================

Outputs in ``out``: ``trials/<name>/`` (each trial's run folder and ``eval.json``), ``tune/``
(Tune's experiment state), ``sweep.json`` (every trial's metrics and the aggregates) and
``summary.md``: one table of every trial's capture rate (Wilson 95 % interval), then per grid
point the interquartile mean (IQM: the mean of the middle half, as rliable computes it with
``scipy.stats.trim_mean(x, 0.25)``) of the capture rates over seeds with a 95 % percentile
bootstrap interval over seeds (10,000 resamples, fixed generator seed).

A sweep rerun into the same ``out`` trains only what is missing: a trial whose run folder holds
the finished training of its config is evaluated again without training, one stopped with a
checkpoint (a killed machine, Ctrl+C) continues from its newest checkpoint
(:func:`accd_gym.learning.training.resume`), as the benchmark's runs do; another config in the
folder starts afresh. (RLlib trials always train afresh.)

In a sweep an RLlib trial samples in its own process (``num_env_runners`` is set to 0) with its
envs stepped on ``cpus_per_trial`` threads: the parallelism is across trials.
"""

from __future__ import annotations

import copy
import itertools
import json
import time
from pathlib import Path
from typing import Any, Optional, Sequence

import numpy as np

from accd_gym import files as _files
from accd_gym.control.registry import CONTROLLERS
from accd_gym.errors import ConfigError
from accd_gym.evals.policies import load_policy
from accd_gym.envs.config import read_json_object
from accd_gym.envs.task import HELD_OUT_WAKE_SEEDS, VALIDATION_WAKE_SEEDS
from accd_gym.evals.episodes import EVAL_BASE_SEED, run_episodes, VALIDATION_BASE_SEED
from accd_gym.learning import rllib, run_state, training
from accd_gym.evals.evaluation import summarize, wilson_interval
from accd_gym.envs.agent_io import AGENT_KEYS
from accd_gym.evals import distributed

#: Defaults of a sweep config.
DEFAULTS: dict[str, Any] = {
    "train_config": None,
    "seeds": [0, 1, 2, 3, 4],
    "grid": {},
    "timesteps": None,
    "episodes": 200,
    "eval_split": "held_out",
    "num_envs": 16,
    "eval_env": None,
    "baselines": [],
    "cpus_per_trial": 1,
    "max_concurrent_trials": 0,
    "ray_address": "local",
}
#: Bootstrap resamples of the interval over seeds, and the seed of their generator.
BOOTSTRAP_RESAMPLES = 10_000
BOOTSTRAP_SEED = 0


def iqm(values: Sequence[float]) -> float:
    """Interquartile mean: the mean after cutting ``int(0.25 n)`` values from each end of the
    sorted values (``scipy.stats.trim_mean(values, 0.25)``, rliable's IQM)."""
    x = np.sort(np.asarray(values, dtype=float))
    n = x.size
    if n == 0:
        raise ValueError("iqm of no values")
    k = int(0.25 * n)
    return float(x[k:n - k].mean())


def bootstrap_interval(values: Sequence[float], stat: Any = iqm, *, resamples: int = BOOTSTRAP_RESAMPLES,
                       seed: int = BOOTSTRAP_SEED, level: float = 0.95) -> tuple[float, float]:
    """Percentile bootstrap interval of ``stat`` over ``values`` resampled with replacement."""
    x = np.asarray(values, dtype=float)
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, x.size, size=(resamples, x.size))
    stats = np.array([stat(x[row]) for row in idx])
    a = (1.0 - level) / 2.0
    return float(np.quantile(stats, a)), float(np.quantile(stats, 1.0 - a))


def load_config(path: str | Path) -> dict[str, Any]:
    """A complete, validated sweep config from a JSON file."""
    return validate_config(read_json_object(path, "sweep config"))


def validate_config(raw: Any) -> dict[str, Any]:
    """Fills in defaults and checks every field (and the training config it names, with every
    grid point applied); ConfigError names the field, value and allowed range."""
    if not isinstance(raw, dict):
        raise ConfigError(f"invalid config: a sweep config must be a JSON object, got {type(raw).__name__}")
    unknown = set(raw) - set(DEFAULTS) - {"description"}
    if unknown:
        raise ConfigError(f"invalid config: sweep config key(s) {sorted(unknown)} outside the allowed set {sorted(DEFAULTS)}")
    cfg = copy.deepcopy(DEFAULTS)
    cfg.update(raw)
    if not isinstance(cfg["train_config"], str):
        raise ConfigError(f"invalid config: `train_config` = {cfg['train_config']!r} is outside the allowed range: a path to a training config")
    seeds = cfg["seeds"]
    if (not isinstance(seeds, list) or not seeds or len(set(seeds)) != len(seeds)
            or any(not isinstance(s, int) or isinstance(s, bool) or not 0 <= s < 2**32 for s in seeds)):
        raise ConfigError(f"invalid config: `seeds` = {seeds!r} is outside the allowed range: a non-empty list of distinct integers in [0, 2^32)")
    for key, low in (("episodes", 1), ("num_envs", 1), ("cpus_per_trial", 1), ("max_concurrent_trials", 0)):
        v = cfg[key]
        if not isinstance(v, int) or isinstance(v, bool) or v < low:
            raise ConfigError(f"invalid config: `{key}` = {v!r} is outside the allowed range: an integer >= {low}")
    if cfg["eval_split"] not in EVAL_SPLITS:
        raise ConfigError(f"invalid config: `eval_split` = {cfg['eval_split']!r} is outside the allowed range {list(EVAL_SPLITS)}")
    wake_seeds, _ = eval_episodes(cfg["eval_split"])
    if cfg["episodes"] > len(wake_seeds):
        raise ConfigError(f"invalid config: `episodes` = {cfg['episodes']} is outside the allowed range 1..{len(wake_seeds)} "
                          f"({cfg['eval_split']} wake seeds)")
    t = cfg["timesteps"]
    if t is not None and (not isinstance(t, int) or isinstance(t, bool) or t < 1):
        raise ConfigError(f"invalid config: `timesteps` = {t!r} is outside the allowed range: null or an integer >= 1")
    if cfg["eval_env"] is not None and not isinstance(cfg["eval_env"], dict):
        raise ConfigError(f"invalid config: `eval_env` = {cfg['eval_env']!r} is outside the allowed range: null or a JSON object")
    if not isinstance(cfg["baselines"], list) or [b for b in cfg["baselines"] if b not in CONTROLLERS]:
        raise ConfigError(f"invalid config: `baselines` = {cfg['baselines']!r} is outside the allowed values: a list of "
                          f"{sorted(CONTROLLERS)}")
    grid = cfg["grid"]
    if not isinstance(grid, dict) or any(not isinstance(v, list) or not v for v in grid.values()):
        raise ConfigError(f"invalid config: `grid` = {grid!r} is outside the allowed range: an object of non-empty lists")
    if "seed" in grid:
        raise ConfigError("invalid config: `grid` key 'seed' is outside the allowed set: training seeds go in `seeds`")
    for point in grid_points(grid):
        train_config(cfg, point, seeds[0])  # raises ConfigError naming the bad field
    return cfg


#: The episode sets a sweep can evaluate on (``eval_split``).
EVAL_SPLITS = ("held_out", "validation")


def eval_episodes(split: str) -> tuple[range, int]:
    """(wake seeds, base seed) of the evaluation episodes of ``split`` (one of :data:`EVAL_SPLITS`):
    episode k has wake seed ``wake_seeds[k]`` and seed ``base + k``."""

    if split == "held_out":
        return HELD_OUT_WAKE_SEEDS, EVAL_BASE_SEED
    if split == "validation":
        return VALIDATION_WAKE_SEEDS, VALIDATION_BASE_SEED
    raise ConfigError(f"invalid config: `eval_split` = {split!r} is outside the allowed range {list(EVAL_SPLITS)}")


def grid_points(grid: dict[str, list[Any]]) -> list[dict[str, Any]]:
    """Every combination of the grid's values (one empty point for an empty grid)."""
    keys = sorted(grid)
    return [dict(zip(keys, values)) for values in itertools.product(*(grid[k] for k in keys))]


def _set_dotted(cfg: dict[str, Any], key: str, value: Any) -> None:
    """Sets ``cfg["a"]["b"] = value`` for ``key = "a.b"`` (creating objects on the way)."""
    parts = key.split(".")
    node = cfg
    for part in parts[:-1]:
        child = node.setdefault(part, {})
        if not isinstance(child, dict):
            raise ConfigError(f"invalid config: grid key {key!r}: {part!r} is not a JSON object in the training config")
        node = child
    node[parts[-1]] = value


def train_config(sweep: dict[str, Any], point: dict[str, Any], seed: int) -> dict[str, Any]:
    """The validated training config of one trial: the sweep's ``train_config`` with the grid
    point, the seed and ``timesteps`` applied (RLlib trials sample in-process)."""
    raw = read_json_object(sweep["train_config"], "`train_config` (training config)")
    for key, value in point.items():
        _set_dotted(raw, key, value)
    raw["seed"] = seed
    if sweep["timesteps"] is not None:
        raw["total_timesteps"] = sweep["timesteps"]
    if rllib.is_rllib_config(raw):
        raw["num_env_runners"] = 0
        raw["num_threads"] = sweep["cpus_per_trial"]
        return rllib.validate_config(raw)
    raw["num_threads"] = sweep["cpus_per_trial"]
    return training.validate_config(raw)


def trial_name(seed: int, point: dict[str, Any]) -> str:
    """The folder name of a trial: ``seed<S>`` and the grid point's values."""
    return f"seed{seed}" + "".join(f"_{k.split('.')[-1]}={v}" for k, v in sorted(point.items()))


def train_trial(cfg: dict[str, Any], run: Path) -> tuple[dict[str, Any], float]:
    """Trains a trial's validated config into its run folder, or reuses the finished training of
    that config there, or continues the one stopped with a checkpoint there (RLlib trials:
    always afresh). Returns the run summary and the trial's training time in seconds as its
    run.json records it (a part cut short by a killed process, which wrote no summary, is not
    in it)."""
    t0 = time.perf_counter()
    if rllib.is_rllib_config(cfg):
        meta = rllib.train(cfg, run, progress=False, connect=False)
    elif run_state.trained(run, cfg):  # the sweep rerun: this trial's training is done
        meta = json.loads((run / "run.json").read_text())
    elif run_state.continues(run, cfg):  # stopped with a checkpoint: continue from it
        meta = training.resume(run, progress=False)
    else:
        run_state.set_aside(run)  # another config's training (or an unsaved one): kept under out/superseded
        meta = training.train(cfg, run, progress=False)
    return meta, meta.get("wall_time_s", time.perf_counter() - t0)


def _trial(params: dict[str, Any]) -> None:
    """One Tune trial: trains into its own run folder, evaluates on the sweep's episodes
    (``eval_split``), reports."""
    from ray import tune


    sweep, point, seed = params["sweep"], params["point"], params["seed"]
    cfg = train_config(sweep, point, seed)
    name = trial_name(seed, point)
    run = Path(params["out"]) / "trials" / name
    meta, train_s = train_trial(cfg, run)
    if meta["status"] != "done":
        raise RuntimeError(f"trial {name}: training {meta['status']} at {meta['timesteps']} steps; "
                           "rerun the sweep to continue it from its checkpoint")
    episodes = sweep["episodes"]
    env = cfg["env"] if sweep["eval_env"] is None else sweep["eval_env"]
    policy = load_policy(str(run))
    wake_seeds, base_seed = eval_episodes(sweep["eval_split"])
    eps = run_episodes(policy, episodes, seed=base_seed, wake_seeds=list(wake_seeds[:episodes]),
                       num_envs=sweep["num_envs"], num_threads=sweep["cpus_per_trial"], config=env)
    s = summarize(eps)
    doc = {"trial": name, "seed": seed, "point": point, "trainer": "rllib" if rllib.is_rllib_config(cfg) else "sb3",
           "algo": cfg["algo"], "timesteps": meta["timesteps"], "status": meta["status"], "train_wall_s": round(train_s, 2),
           "steps_per_s": meta.get("steps_per_s"), "episodes": episodes, "captures": s["captures"],
           "capture_rate": s["capture_rate"], "capture_rate_ci95": s["capture_rate_ci95"],
           "miss_distance_median_m": s["miss_distance_m"]["median"], "run": str(run)}
    _files.write_text(run / "eval.json", json.dumps({"summary": s, "trial": doc}, indent=1))
    # The driver builds its table from the reported metrics: no shared filesystem needed for it.
    tune.report({k: v for k, v in doc.items() if k not in ("point", "capture_rate_ci95")})


#: The trial metrics the table is made of (reported by each trial through Tune).
_REPORTED = ("trial", "seed", "trainer", "algo", "timesteps", "status", "train_wall_s", "steps_per_s", "episodes",
             "captures", "capture_rate", "miss_distance_median_m", "run")


def aggregate(trials: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per grid point: IQM and mean capture rate over seeds, with the bootstrap interval of the IQM."""
    groups: dict[str, list[dict[str, Any]]] = {}
    for t in trials:
        groups.setdefault(json.dumps(t["point"], sort_keys=True), []).append(t)
    out = []
    for key, ts in sorted(groups.items()):
        rates = [t["capture_rate"] for t in sorted(ts, key=lambda t: t["seed"])]
        lo, hi = bootstrap_interval(rates)
        out.append({"point": json.loads(key), "seeds": sorted(t["seed"] for t in ts), "iqm": iqm(rates),
                    "iqm_ci95_bootstrap": [lo, hi], "mean": float(np.mean(rates)), "min": min(rates), "max": max(rates)})
    return out


def baseline_rates(sweep: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """The sweep's ``baselines`` on its evaluation episodes (``eval_split``, ``episodes``), each on
    the evaluation env without the agent's options: {name: captures, episodes, capture_rate, its
    Wilson 95 % interval, miss median}."""

    env = sweep["eval_env"]
    if env is None:
        env = read_json_object(sweep["train_config"], "train_config (training config)").get("env") or {}
    env = {k: v for k, v in env.items() if k not in AGENT_KEYS}
    wake_seeds, base_seed = eval_episodes(sweep["eval_split"])
    out = {}
    for name in sweep["baselines"]:
        eps = run_episodes(load_policy(name, 0, config=env), sweep["episodes"], seed=base_seed,
                           wake_seeds=list(wake_seeds[:sweep["episodes"]]), num_envs=sweep["num_envs"], config=env)
        s = summarize(eps)
        out[name] = {"captures": s["captures"], "episodes": sweep["episodes"], "capture_rate": s["capture_rate"],
                     "capture_rate_ci95": list(s["capture_rate_ci95"]), "miss_distance_median_m": s["miss_distance_m"]["median"]}
    return out


def _episodes_line(cfg: dict[str, Any]) -> str:
    if cfg.get("eval_split", "held_out") == "validation":
        return (f"Validation: {cfg['episodes']} episodes of training wake seeds (`VALIDATION_WAKE_SEEDS`), the same "
                "episodes for every trial; the held-out set is not used.")
    return f"Held-out evaluation: the first {cfg['episodes']} held-out wake seeds, the same episodes for every trial."


def summary_markdown(doc: dict[str, Any]) -> str:
    """The sweep's table: every trial, then the aggregates over seeds per grid point."""
    lines = [f"# Sweep: {len(doc['trials'])} trials of `{doc['config']['train_config']}`", "",
             _episodes_line(doc["config"]) + f" Wall time {doc['wall_time_s']:.0f} s.", "",
             "| trial | seed | grid point | trainer | steps | capture rate | 95 % CI (Wilson) | miss median (m) | training steps/s |",
             "|---|---|---|---|---|---|---|---|---|"]
    for t in doc["trials"]:
        lo, hi = t["capture_rate_ci95"]
        point = ", ".join(f"{k}={v}" for k, v in sorted(t["point"].items())) or "-"
        lines.append(f"| {t['trial']} | {t['seed']} | {point} | {t['trainer']} {t['algo'].upper()} | {t['timesteps']} "
                     f"| {t['captures']}/{t['episodes']} = {t['capture_rate']:.1%} | {lo:.1%} - {hi:.1%} "
                     f"| {t['miss_distance_median_m']:.2f} | {t['steps_per_s']} |")
    for f in doc["failed"]:
        outcome = f["error"] if f["error"] == UNFINISHED else f"failed: {f['error']}"
        lines.append(f"| {f['trial']} | {f['seed']} | {f['point']} | {outcome} | | | | | |")
    for name, b in doc.get("baselines", {}).items():
        lo, hi = b["capture_rate_ci95"]
        lines.append(f"| baseline {name} | - | - | - | - | {b['captures']}/{b['episodes']} = {b['capture_rate']:.1%} "
                     f"| {lo:.1%} - {hi:.1%} | {b['miss_distance_median_m']:.2f} | - |")
    lines += ["", "| grid point | seeds | IQM capture rate | 95 % bootstrap interval over seeds | mean | min - max |",
              "|---|---|---|---|---|---|"]
    for a in doc["aggregates"]:
        point = ", ".join(f"{k}={v}" for k, v in sorted(a["point"].items())) or "-"
        lo, hi = a["iqm_ci95_bootstrap"]
        lines.append(f"| {point} | {len(a['seeds'])} | {a['iqm']:.1%} | {lo:.1%} - {hi:.1%} | {a['mean']:.1%} "
                     f"| {a['min']:.1%} - {a['max']:.1%} |")
    lines += ["", "IQM: mean of the middle half of the seeds' capture rates (rliable's IQM); interval: percentile "
              f"bootstrap over seeds, {BOOTSTRAP_RESAMPLES} resamples. With few seeds the interval is wide and coarse."]
    return "\n".join(lines) + "\n"


def _signal_handlers() -> dict[int, Any]:
    """This process's SIGINT/SIGTERM/SIGUSR1 handlers (none off the main thread; Windows has no
    SIGUSR1)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return {}
    names = ("SIGINT", "SIGTERM", "SIGUSR1")
    return {sig: signal.getsignal(sig) for sig in (getattr(signal, n) for n in names if hasattr(signal, n))}


def _restore_signal_handlers(kept: dict[int, Any]) -> None:
    """Puts back handlers saved by :func:`_signal_handlers`."""
    import signal

    for sig, handler in kept.items():
        if handler is not None:
            signal.signal(sig, handler)


#: What the sweep document says of a trial that neither finished nor raised: the sweep stopped
#: (Ctrl+C) before or while it ran.
UNFINISHED = "unfinished: the sweep stopped before this trial ended (a rerun into the same --out resumes it)"


def trial_record(params: dict[str, Any], metrics: Optional[dict[str, Any]], error: Any) -> tuple[bool, dict[str, Any]]:
    """A Tune trial's entry in the sweep document: ``(True, its reported metrics)`` for a trial
    that finished with its evaluation, else ``(False, {"trial", "seed", "point", "error"})``,
    the error its exception's text or :data:`UNFINISHED` when it raised none."""
    m = metrics or {}
    if error is None and "capture_rate" in m:
        t = {k: m[k] for k in _REPORTED if k in m}
        t.update(point=params["point"], capture_rate_ci95=list(wilson_interval(int(m["captures"]), int(m["episodes"]))))
        return True, t
    text = UNFINISHED if error is None else " ".join(str(error).split())[:200]
    return False, {"trial": trial_name(params["seed"], params["point"]), "seed": params["seed"], "point": params["point"],
                   "error": text}


def run(config: dict[str, Any] | str | Path, out: str | Path, *, progress: bool = True) -> dict[str, Any]:
    """Runs a sweep (a validated config or its file) into ``out``; returns the sweep document
    (also ``out/sweep.json``; the table in ``out/summary.md``)."""

    cfg = config if isinstance(config, dict) else load_config(config)
    cfg = validate_config(cfg)
    cfg["train_config"] = str(Path(cfg["train_config"]).resolve())
    # before Ray starts: a read-only folder or a special file among the outputs is refused at once
    out = _files.writable_folder(Path(out).resolve(), "--out", ("sweep.json", "summary.md"))
    ray = distributed.connect(cfg["ray_address"])
    from ray import tune

    t0 = time.perf_counter()
    points = grid_points(cfg["grid"])
    trainable = tune.with_resources(_trial, {"cpu": cfg["cpus_per_trial"]})
    tuner = tune.Tuner(
        trainable,
        param_space={"sweep": cfg, "out": str(out), "seed": tune.grid_search(cfg["seeds"]),
                     "point": tune.grid_search(points)},
        tune_config=tune.TuneConfig(max_concurrent_trials=cfg["max_concurrent_trials"] or None),
        run_config=tune.RunConfig(storage_path=str(out / "tune"), name="sweep", verbose=1 if progress else 0),
    )
    # Tune installs its own SIGINT (and SIGUSR1) handler and leaves it after the run; restore
    # ours, or the next Ctrl+C in this process would not raise KeyboardInterrupt.
    kept = _signal_handlers()
    try:
        grid = tuner.fit()
    finally:
        _restore_signal_handlers(kept)
    trials, failed = [], []
    for result in grid:
        finished, record = trial_record(result.config, result.metrics, result.error)
        (trials if finished else failed).append(record)
    trials.sort(key=lambda t: (json.dumps(t["point"], sort_keys=True), t["seed"]))
    doc = {"config": cfg, "trials": trials, "failed": failed, "aggregates": aggregate(trials) if trials else [],
           "baselines": baseline_rates(cfg),
           "wall_time_s": time.perf_counter() - t0, "cluster_cpus": int(ray.cluster_resources().get("CPU", 0))}
    _files.write_text(out / "sweep.json", json.dumps(doc, indent=1))
    _files.write_text(out / "summary.md", summary_markdown(doc))
    return doc


__all__ = ["DEFAULTS", "EVAL_SPLITS", "UNFINISHED", "aggregate", "baseline_rates", "bootstrap_interval", "eval_episodes", "grid_points",
           "iqm", "load_config", "run", "summary_markdown", "train_config", "train_trial", "trial_name", "trial_record",
           "validate_config"]

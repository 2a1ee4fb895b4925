"""The benchmark suite (``accd-gym benchmark``): every tier (:mod:`accd_gym.envs.tiers`), learned policies
trained with several seeds, every baseline, the same held-out episodes, one report.

``accd-gym benchmark --config training/benchmark.json --out runs/benchmark`` calls :func:`run`:

1. **Training** (one job per tier, algorithm and seed): the algorithm's training recipe
   (``train_config``, e.g. training/ppo.json) with the tier as its env and the job's seed, trained
   for ``timesteps`` on training wake seeds, then evaluated on the tier's first ``episodes``
   held-out episodes (episode k: seed 20240607 + k, held-out wake seed k, so every policy of a
   tier meets the same episodes) and on its first ``validation_episodes`` validation episodes
   (episode k: seed 7340033 + k, validation wake seed k: training wake seeds never drawn by
   training). Jobs run one after the other in this process, or, with
   ``--ray ADDRESS`` (``"local"``, ``"auto"``, ``HOST:PORT``), as Ray tasks of ``cpus_per_job``
   CPUs each, placed wherever the cluster has room (the same machinery as ``evaluate --ray``),
   the longest first. Resumable: a finished job's result stays in ``OUT/runs/<job>/result.json``
   and a rerun into the same ``OUT`` reuses it while its key (:func:`job_key`: job, training
   config, tier, build, evaluation) is unchanged; a finished training whose evaluation is stale
   is evaluated again without retraining; an interrupted training continues from its
   checkpoint (:func:`run_job`). A recipe with ``"trainer": "distill"`` (behaviour cloning,
   DAgger: :mod:`accd_gym.learning.distill`; its ``timesteps`` are the labelled steps of all its
   rounds) is trained, resumed and evaluated the same way. ``--tiers``, ``--algos``, ``--seeds`` (:func:`selection`) run
   only some jobs; the report covers every finished job in ``OUT`` and lists the others under
   "Missing / unfinished runs". Ctrl+C: the training under way writes its checkpoint, the report
   is written from what is finished, exit code 130.
2. **Baselines** (the config's ``baselines``: trivial references such as ``zero`` and ``random``, and
   the classical controllers ``guidance``, ``lqr`` and ``mpc``) on the same held-out and
   validation episodes of every tier; the LQR and MPC are designed for each tier's configuration. Each baseline's record is stored once
   in ``OUT/baselines`` and reused by a rerun while its key is unchanged.
3. **Report** (``OUT/benchmark.json``, ``OUT/benchmark.md``, ``OUT/performance_profile.png``):
   per tier and policy the capture rate (learned: the interquartile mean over seeds with a 95 %
   stratified bootstrap interval, and every seed's rate; baselines: the rate with its Wilson
   interval), the median miss distance and time to capture, and the paired exact McNemar test
   (:func:`accd_gym.evals.evaluation.mcnemar_exact`) of the chosen learned run against the chosen
   classical baseline on the same held-out episodes; a summary of the best classical controller,
   the best hybrid method (a learned correction of a classical controller's command) and the best
   standalone learned method per tier (:func:`summarize`, chosen on the validation episodes); the
   learned methods normalized by the best classical controller (= 1.0) with rliable's probability
   of improvement over it (:func:`probability_of_improvement`); the two Target sections
   (:func:`target`: any learned method, and a standalone one); a performance profile over every
   (tier, seed) run. ``--docs`` also writes the report to docs/benchmark.md and the plot to
   docs/figures/; ``--readme`` rewrites the README's results table (:func:`write_readme_table`).

**Statistics.** IQM: the mean of the middle half of the seeds' rates (rliable's IQM,
``scipy.stats.trim_mean(x, 0.25)``). Interval: a two-level bootstrap stratified by seed: resample
the seeds with replacement, then each resampled seed's episodes with replacement (drawn exactly as
``Binomial(n, rate) / n``), IQM of the resampled rates; 10,000 resamples, percentile interval, a
fixed generator seed.

**Selection on validation episodes.** Every choice the report makes is made on the validation
episodes alone (:func:`choose_run`, :func:`choose_method`): each method's chosen run (the one
``scripts/ship_policies.py`` ships, recomputable from the benchmark folder with
:func:`chosen_run`), the best learned method, run and classical baseline that the McNemar test
and the Target section compare. The held-out episodes only report: a choice never sees them, so
the p-values are those of comparisons fixed before the held-out episodes were looked at.

Config (JSON object, every key optional; ``quick`` holds the overrides ``--quick`` applies):

===================== ===================================================================================
key                   meaning
===================== ===================================================================================
tiers                 tier names (default: all)
learners              ``{"ppo": {"train_config", "seeds", "timesteps", "tiers"}, "sac": {...}}``;
                      ``tiers`` limits an algorithm to some tiers (default: all); ``train_config`` a
                      recipe, or ``{tier: recipe}`` (then its tiers by default); the recipe's env
                      options (residual, history) are kept, its tier set to the job's;
                      ``init_from`` another learner's name: each job starts from that learner's
                      run of the same tier and seed (RL fine-tuning of a distilled student), after
                      the jobs that start afresh; ``teacher_from`` another learner's name (for a
                      distillation recipe): each job's teacher is that learner's run of the same
                      tier chosen on the validation episodes (e.g. DAgger from the best residual
                      policy), after the jobs that start afresh
baselines             baseline names (default ``["zero", "random", "guidance", "lqr"]``; unknown ones
                      are refused)
episodes              held-out episodes per tier (default 500)
validation_episodes   validation episodes per tier, on which every choice is made (default 500)
num_envs              evaluation batch (default 16)
cpus_per_job          CPUs a Ray job reserves, also the threads stepping its envs and at most those of
                      PyTorch in its gradient updates (default 1)
quick                 overrides for ``--quick`` (its ``learners`` are the quick run's only ones)
===================== ===================================================================================
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import json
import platform
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

import numpy as np

from accd_gym.control.registry import CONTROLLERS
from accd_gym.errors import ConfigError
from accd_gym.evals.policies import load_policy
from accd_gym.envs.tiers import merge, tier as _tier, TIERS
from accd_gym.envs.task import HELD_OUT_WAKE_SEEDS, VALIDATION_WAKE_SEEDS
from accd_gym.envs.config import read_json_object
from accd_gym.evals.episodes import EVAL_BASE_SEED, VALIDATION_BASE_SEED, run_episodes
from accd_gym import _core, files
from accd_gym.learning import distill, run_state, training
from accd_gym.evals import distributed
from accd_gym.evals.sweep import iqm as _iqm
from accd_gym.evals.evaluation import mcnemar_exact, wilson_interval
from accd_gym.files import save_figure
from accd_gym.control.lqr import blas_kernels

#: Defaults of a benchmark config.
DEFAULTS: dict[str, Any] = {
    "tiers": None,
    "learners": {
        "ppo": {"train_config": "training/ppo.json", "seeds": [0, 1, 2, 3, 4], "timesteps": 1_000_000, "tiers": None},
    },
    "baselines": ["zero", "random", "guidance", "lqr"],
    "episodes": 500,
    "validation_episodes": 500,
    "num_envs": 16,
    "cpus_per_job": 1,
    "quick": {},
}
#: Bootstrap resamples and the seed of their generator.
BOOTSTRAP_RESAMPLES = 10_000
BOOTSTRAP_SEED = 0
_LEARNER_KEYS = ("train_config", "seeds", "timesteps", "tiers", "init_from", "teacher_from")


def validate_config(raw: Any, *, quick: bool = False, root: Optional[Path] = None) -> dict[str, Any]:
    """A complete benchmark config: ``raw`` over :data:`DEFAULTS` (with ``--quick``, its
    ``quick`` overrides on top), every key checked; ConfigError naming the key otherwise.
    Relative ``train_config`` paths are resolved against ``root`` (the config file's folder's
    parent, the repository, by default the working directory)."""
    if not isinstance(raw, dict):
        raise ConfigError(f"invalid config: a benchmark config must be a JSON object, not {type(raw).__name__}")
    unknown = sorted(set(raw) - set(DEFAULTS) - {"description", "source"})
    if unknown:
        raise ConfigError(f"invalid config: benchmark key(s) {unknown} outside the allowed set {sorted(DEFAULTS)}")
    cfg = merge(DEFAULTS, {k: v for k, v in raw.items() if k not in ("description", "source")})
    if "learners" in raw:  # the learners named replace the default set, not extend it
        cfg["learners"] = copy.deepcopy(raw["learners"])
    if quick:
        q = cfg.get("quick") or {}
        cfg = merge(cfg, q)
        if "learners" in q:  # the quick run trains only the learners its overrides name
            full = raw.get("learners", DEFAULTS["learners"])
            cfg["learners"] = {k: merge(full[k], v) if k in full else copy.deepcopy(v) for k, v in q["learners"].items()}
    tiers = cfg["tiers"] if cfg["tiers"] is not None else list(TIERS)
    bad = [t for t in tiers if t not in TIERS]
    if bad or not tiers:
        raise ConfigError(f"invalid config: `tiers` = {cfg['tiers']!r} is outside the allowed values: a non-empty list of {list(TIERS)}")
    cfg["tiers"] = list(tiers)
    if not isinstance(cfg["learners"], dict):
        raise ConfigError("invalid config: `learners` must be an object {algo: {train_config, seeds, timesteps, tiers}}")
    base = root or Path.cwd()
    import re

    for algo, spec in cfg["learners"].items():
        if not re.fullmatch(r"[a-z][a-z0-9_]*", algo):
            raise ConfigError(f"invalid config: `learners.{algo}` is outside the allowed names: [a-z][a-z0-9_]*")
        if not isinstance(spec, dict) or set(spec) - set(_LEARNER_KEYS):
            raise ConfigError(f"invalid config: `learners.{algo}` must be an object with keys {list(_LEARNER_KEYS)}")
        if isinstance(spec.get("train_config"), dict):  # a recipe per tier: those tiers by default
            spec.setdefault("tiers", list(spec["train_config"]))
        spec.setdefault("tiers", None)
        seeds = spec.get("seeds")
        if not isinstance(seeds, list) or not seeds or not all(isinstance(s, int) and s >= 0 for s in seeds):
            raise ConfigError(f"invalid config: `learners.{algo}.seeds` = {seeds!r} is outside the allowed range: a non-empty list of ints >= 0")
        if len(set(seeds)) != len(seeds):
            raise ConfigError(f"invalid config: `learners.{algo}.seeds` = {seeds!r} repeats a seed")
        steps = spec.get("timesteps")
        if not isinstance(steps, int) or steps < 1:
            raise ConfigError(f"invalid config: `learners.{algo}.timesteps` = {steps!r} is outside the allowed range >= 1")
        if spec["tiers"] is not None:
            if not isinstance(spec["tiers"], list) or [t for t in spec["tiers"] if t not in tiers]:
                raise ConfigError(f"invalid config: `learners.{algo}.tiers` = {spec['tiers']!r} is outside the allowed values: a list of {tiers}")
        recipes = spec.get("train_config")
        named = recipes.items() if isinstance(recipes, dict) else [(None, recipes)]
        if isinstance(recipes, dict) and [t for t in (spec["tiers"] or tiers) if t not in recipes]:
            raise ConfigError(f"invalid config: `learners.{algo}.train_config` = {recipes!r} has no recipe for the tiers "
                              f"{[t for t in (spec['tiers'] or tiers) if t not in recipes]}")
        resolved = {}
        for tier_name, recipe in named:
            path = Path(recipe or "") if isinstance(recipe, str) else Path("")
            path = path if path.is_absolute() else base / path
            if not isinstance(recipe, str) or not path.is_file():
                raise ConfigError(f"invalid config: `learners.{algo}.train_config` = {recipe!r} is not a file")
            resolved[tier_name] = str(path)
        spec["train_config"] = resolved if isinstance(recipes, dict) else resolved[None]
    for algo, spec in cfg["learners"].items():
        _check_teacher_from(algo, spec, cfg["learners"], tiers)
        _check_init_from(algo, spec, cfg["learners"], tiers)
    if not isinstance(cfg["baselines"], list) or [b for b in cfg["baselines"] if b not in CONTROLLERS]:
        raise ConfigError(f"invalid config: `baselines` = {cfg['baselines']!r} is outside the allowed values: a list of {list(CONTROLLERS)}")
    for key, lo in (("episodes", 1), ("validation_episodes", 1), ("num_envs", 1), ("cpus_per_job", 1)):
        v = cfg[key]
        if not isinstance(v, int) or isinstance(v, bool) or v < lo:
            raise ConfigError(f"invalid config: `{key}` = {v!r} is outside the allowed range >= {lo}")

    if cfg["episodes"] > len(HELD_OUT_WAKE_SEEDS):
        raise ConfigError(f"invalid config: `episodes` = {cfg['episodes']} is outside the allowed range [1, {len(HELD_OUT_WAKE_SEEDS)}] (the held-out wake seeds)")
    if cfg["validation_episodes"] > len(VALIDATION_WAKE_SEEDS):
        raise ConfigError(f"invalid config: `validation_episodes` = {cfg['validation_episodes']} is outside the allowed "
                          f"range [1, {len(VALIDATION_WAKE_SEEDS)}] (the validation wake seeds)")
    return cfg


def _check_init_from(algo: str, spec: dict[str, Any], learners: dict[str, Any], tiers: list[str]) -> None:
    """ConfigError unless ``learners.<algo>.init_from`` (when set) names another learner of the
    config, itself started afresh, that has a run for each of this learner's tiers and seeds:
    each job starts from the run of the same tier and seed."""
    source = spec.get("init_from")
    if source is None:
        return
    other = _fresh_source(algo, "init_from", source, learners)
    mine, theirs = spec["tiers"] or tiers, other["tiers"] or tiers
    missing = [t for t in mine if t not in theirs] + [f"seed {s}" for s in spec["seeds"] if s not in other["seeds"]]
    if missing:
        raise ConfigError(f"invalid config: `learners.{algo}.init_from` = {source!r} has no run for {missing}: "
                          f"each of {algo}'s jobs starts from the {source} run of its tier and seed")


def _starts_afresh(spec: dict[str, Any]) -> bool:
    """A learner whose jobs depend on no other learner's runs."""
    return spec.get("init_from") is None and spec.get("teacher_from") is None


def _fresh_source(algo: str, key: str, source: Any, learners: dict[str, Any]) -> dict[str, Any]:
    """The learner ``learners.<algo>.<key>`` names; ConfigError unless it is another learner of
    the config that starts afresh."""
    other = learners.get(source) if isinstance(source, str) else None
    if other is None or source == algo or not _starts_afresh(other):
        raise ConfigError(f"invalid config: `learners.{algo}.{key}` = {source!r} is outside the allowed values: "
                          f"another learner of this config that starts afresh "
                          f"({sorted(k for k, v in learners.items() if k != algo and _starts_afresh(v))})")
    return other


def _check_teacher_from(algo: str, spec: dict[str, Any], learners: dict[str, Any], tiers: list[str]) -> None:
    """ConfigError unless ``learners.<algo>.teacher_from`` (when set) names another learner of
    the config, itself started afresh, with runs on each of this learner's tiers, and this
    learner's recipes are distillation recipes (their ``teacher`` is what the option replaces)."""
    source = spec.get("teacher_from")
    if source is None:
        return
    if spec.get("init_from") is not None:
        raise ConfigError(f"invalid config: `learners.{algo}` sets both `init_from` and `teacher_from`: a "
                          "distillation starts afresh from its teacher's labels, a fine-tuning from a run")
    other = _fresh_source(algo, "teacher_from", source, learners)
    mine, theirs = spec["tiers"] or tiers, other["tiers"] or tiers
    missing = [t for t in mine if t not in theirs]
    if missing:
        raise ConfigError(f"invalid config: `learners.{algo}.teacher_from` = {source!r} has no run on the tiers {missing}: "
                          f"each of {algo}'s jobs learns from the {source} run of its tier")
    recipes = spec["train_config"].values() if isinstance(spec["train_config"], dict) else [spec["train_config"]]
    for recipe in recipes:
        if not distill.is_recipe(read_json_object(recipe, "train_config (training config)")):
            raise ConfigError(f"invalid config: `learners.{algo}.teacher_from` = {source!r} needs distillation recipes "
                              f"(\"trainer\": \"distill\"); {recipe!r} is not one")


def load_config(path: str | Path, *, quick: bool = False) -> dict[str, Any]:
    """A validated benchmark config from a JSON file (paths in it relative to the repository,
    the file's folder's parent)."""
    p = Path(path).resolve()
    cfg = validate_config(read_json_object(p, "benchmark config"), quick=quick, root=p.parent.parent)
    cfg["source"] = str(p)
    return cfg


@dataclass(frozen=True)
class Job:
    """One training run of the benchmark: an algorithm's recipe on a tier with a seed;
    ``init_from``: the learner whose run of the same tier and seed it starts from (RL
    fine-tuning of a distilled student), or None; ``teacher_from``: the learner whose run of the
    same tier, chosen on the validation episodes, teaches it (a distillation), or None, and
    ``teacher`` that run's folder name once chosen (:func:`with_teacher`)."""

    tier: str
    algo: str
    seed: int
    train_config: str
    timesteps: int
    init_from: Optional[str] = None
    teacher_from: Optional[str] = None
    teacher: Optional[str] = None

    @property
    def name(self) -> str:
        """The run's folder name."""
        return f"{self.tier}_{self.algo}_seed{self.seed}"

    @property
    def starts_afresh(self) -> bool:
        """Whether the job depends on no other learner's runs (no ``init_from``, no ``teacher_from``)."""
        return self.init_from is None and self.teacher_from is None

    @property
    def source(self) -> Optional[str]:
        """The folder name of the run it starts from (None: it starts afresh)."""
        return None if self.init_from is None else f"{self.tier}_{self.init_from}_seed{self.seed}"


def jobs(cfg: dict[str, Any]) -> list[Job]:
    """Every training job of a validated config, in (tier, algorithm, seed) order."""
    out = []
    for tier in cfg["tiers"]:
        for algo, spec in cfg["learners"].items():
            if spec["tiers"] is not None and tier not in spec["tiers"]:
                continue
            recipe = spec["train_config"][tier] if isinstance(spec["train_config"], dict) else spec["train_config"]
            out += [Job(tier, algo, s, recipe, spec["timesteps"], spec.get("init_from"), spec.get("teacher_from"))
                    for s in spec["seeds"]]
    return out


def selection(cfg: dict[str, Any], tiers: Optional[Sequence[str]] = None, algos: Optional[Sequence[str]] = None,
              seeds: Optional[Sequence[int]] = None) -> Callable[[Job], bool]:
    """Which jobs of a validated config to run (None: every value); ConfigError naming the option,
    the value and the allowed ones for a tier, algorithm or seed the config does not have."""
    allowed = {"--tiers": list(cfg["tiers"]), "--algos": list(cfg["learners"]),
               "--seeds": sorted({s for spec in cfg["learners"].values() for s in spec["seeds"]})}
    for option, values in (("--tiers", tiers), ("--algos", algos), ("--seeds", seeds)):
        for v in values or []:
            if v not in allowed[option]:
                raise ConfigError(f"invalid config: {option} {v!r} is outside the allowed range {allowed[option]}")

    def chosen(job: Job) -> bool:
        return ((tiers is None or job.tier in tiers) and (algos is None or job.algo in algos)
                and (seeds is None or job.seed in seeds))

    return chosen


def _episode_record(eps: Sequence[Any]) -> dict[str, Any]:
    """What the report needs of an evaluation: per episode, captured, miss distance, capture time."""
    return {
        "captured": [bool(e.captured) for e in eps],
        "min_distance": [float(e.min_distance) for e in eps],
        "capture_time": [None if e.capture_time is None else float(e.capture_time) for e in eps],
        "outcome": [e.outcome for e in eps],
        "closest_speed": [e.closest_speed for e in eps],
        "final_speed": [e.final_speed for e in eps],
    }


def _median(values: Sequence[Optional[float]]) -> Optional[float]:
    """The median of the values that are not None (None without any)."""
    v = [x for x in values if x is not None]
    return float(np.median(v)) if v else None


def failures(records: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Where a method's episodes (pooled over its seeds' records) fail and how it captures: the
    missed episodes' count, outcomes, median miss distance and closing speed at the closest
    approach; the captured episodes' median closing speed at capture and time to capture."""
    rows = [{k: rec[k][i] if k in rec else None for k in ("captured", "outcome", "min_distance", "closest_speed",
                                                          "final_speed", "capture_time")}
            for rec in records for i in range(len(rec["captured"]))]
    missed = [r for r in rows if not r["captured"]]
    caught = [r for r in rows if r["captured"]]
    outcomes: dict[str, int] = {}
    for r in missed:
        outcomes[r["outcome"]] = outcomes.get(r["outcome"], 0) + 1
    return {"episodes": len(rows), "missed": len(missed), "outcomes": outcomes,
            "missed_miss_median_m": _median([r["min_distance"] for r in missed]),
            "missed_closest_speed_median_mps": _median([r["closest_speed"] for r in missed]),
            "capture_speed_median_mps": _median([r["final_speed"] for r in caught]),
            "capture_time_median_s": _median([r["capture_time"] for r in caught])}


def evaluate_policy(policy: Any, tier: str, episodes: int, num_envs: int, num_threads: int = 0, *,
                    validation: bool = False) -> dict[str, Any]:
    """``policy`` on the tier's first ``episodes`` held-out episodes (``validation``: validation
    episodes, seed :data:`~accd_gym.evals.episodes.VALIDATION_BASE_SEED` + k and validation wake
    seed k): the per-episode record."""

    wake, seed = (VALIDATION_WAKE_SEEDS, VALIDATION_BASE_SEED) if validation else (HELD_OUT_WAKE_SEEDS, EVAL_BASE_SEED)
    eps = run_episodes(policy, episodes, seed=seed, wake_seeds=list(wake[:episodes]), num_envs=num_envs,
                       num_threads=num_threads, config={"tier": tier})
    return _episode_record(eps)


def validation_rate(captured: Sequence[bool]) -> float:
    """The capture rate of a validation record's ``captured`` list."""
    if not len(captured):
        raise ConfigError("invalid config: a validation record without episodes cannot choose a run")
    return float(np.mean(np.asarray(captured, dtype=bool)))


def choose_run(validation: dict[str, Sequence[bool]]) -> str:
    """The run (or baseline) with the highest capture rate on its validation episodes
    (``{name: captured}``), ties to the greatest name. The one way the benchmark and
    ``scripts/ship_policies.py`` choose a run: it is given validation records alone."""
    if not validation:
        raise ConfigError("invalid config: no validation records to choose a run from")
    return max(validation, key=lambda k: (validation_rate(validation[k]), k))


def choose_method(validation: dict[str, dict[str, Sequence[bool]]]) -> str:
    """The method (``{method: {run: captured}}``, validation episodes) whose runs' validation
    rates have the highest IQM, ties to the greatest name."""
    if not validation or not all(validation.values()):
        raise ConfigError("invalid config: no validation records to choose a method from")
    return max(validation, key=lambda m: (iqm([validation_rate(c) for c in validation[m].values()]), m))


def chosen_run(folder: str | Path, tier: str, algo: str) -> dict[str, Any]:
    """The run of method ``algo`` on ``tier`` that a finished benchmark folder (``accd-gym
    benchmark --out``) chooses (:func:`choose_run` over the runs' stored validation records):
    ``{"name", "validation_rate", "validation_episodes", "candidates": {name: rate}}``.
    ConfigError naming the folder when it has no such run with a validation record."""
    runs: dict[str, Sequence[bool]] = {}
    for path in sorted((Path(folder) / "runs").glob(f"{tier}_{algo}_seed*/{RESULT_FILE}")):
        result = read_json_object(path, "benchmark result").get("result", {})
        job = result.get("job", {})
        if job.get("tier") == tier and job.get("algo") == algo and "validation" in result:
            runs[result["name"]] = result["validation"]["captured"]
    if not runs:
        raise ConfigError(f"invalid config: benchmark folder {folder} has no finished {algo} run on {tier} with a "
                          "validation record (rerun `accd-gym benchmark` into it)")
    name = choose_run(runs)
    return {"name": name, "validation_rate": validation_rate(runs[name]), "validation_episodes": len(runs[name]),
            "candidates": {k: validation_rate(v) for k, v in sorted(runs.items())}}


#: A finished job's result in its run folder: what a rerun of the benchmark into the same
#: ``--out`` reuses when the job's key (:func:`job_key`) is unchanged.
RESULT_FILE = "result.json"


@functools.lru_cache(maxsize=1)
def digest_sources() -> list[Path]:
    """The files :func:`build_digest` hashes: the native extension and every Python source of the
    package (envs, control, learning, evals, ...), in a fixed order."""
    package = Path(_core.__file__).parent
    return [Path(_core.__file__), *sorted(package.rglob("*.py"))]


def build_digest() -> str:
    """SHA-256 of the code a result comes from: the native extension's bytes and the package's
    Python sources (the version number alone does not change with a rebuild)."""
    import hashlib

    sources = digest_sources()
    package = sources[0].parent
    h = hashlib.sha256()
    for src in sources:
        h.update(src.relative_to(package).as_posix().encode())
        h.update(src.read_bytes())
    return h.hexdigest()


def job_key(job: Job, episodes: int, num_envs: int, validation_episodes: Optional[int] = None) -> dict[str, Any]:
    """What a job's result depends on: the job, the training config's bytes (SHA-256), the tier's
    configuration, the code (:func:`build_digest`), the evaluation's held-out and validation
    episodes (``validation_episodes`` None: as many as ``episodes``) and batch size. A stored
    result with another key is not reused."""
    # The recipe by its name and bytes, not its path: a benchmark folder stays valid for a moved
    # or freshly cloned checkout.
    # (init_from and the teacher only where set: the keys of the jobs that start afresh are those
    # they always had)
    optional = ("init_from", "teacher_from", "teacher")
    fields = {k: v for k, v in job.__dict__.items() if not (k in optional and v is None)}
    return {"job": {**fields, "train_config": Path(job.train_config).name},
            "train_config_sha256": _sha256(job.train_config),
            "tier_config": _tier(job.tier).config(), "build": build_digest(), "episodes": episodes,
            "validation_episodes": episodes if validation_episodes is None else validation_episodes,
            "num_envs": num_envs}


def _sha256(path: str | Path) -> str:
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _portable(config: dict[str, Any]) -> dict[str, Any]:
    """``config`` with every learner's recipe path replaced by its file name and SHA-256, and the
    config file's path (``source``) by its name: what :func:`_claim` records and compares,
    independent of where the checkout lies."""
    out = json.loads(json.dumps(config))
    if isinstance(out.get("source"), str):
        out["source"] = Path(out["source"]).name
    for spec in out.get("learners", {}).values():
        recipe = spec.get("train_config")
        if isinstance(recipe, dict):
            spec["train_config"] = {t: {"file": Path(p).name, "sha256": _sha256(p)} for t, p in recipe.items()}
        elif isinstance(recipe, str):
            spec["train_config"] = {"file": Path(recipe).name, "sha256": _sha256(recipe)}
    return out


def _start_folder(out: str | Path, job: Job) -> Optional[Path]:
    """The run folder a fine-tuning job starts from (its learner's ``init_from``: the run of the
    same tier and seed in ``out``), or None for a job that starts afresh."""
    return None if job.source is None else Path(out).resolve() / "runs" / job.source


def _teacher_folder(out: str | Path, job: Job) -> Optional[Path]:
    """The run folder that teaches a distillation job (its learner's ``teacher_from``: the run
    :func:`with_teacher` chose in ``out``), or None for a job without one."""
    return None if job.teacher is None else Path(out).resolve() / "runs" / job.teacher


def with_teacher(job: Job, out: str | Path, cfg: dict[str, Any]) -> Job:
    """``job`` with its teacher chosen, for a learner with ``teacher_from``: the run of that
    learner on the job's tier with the highest capture rate on the validation episodes
    (:func:`choose_run`; every seed of the config, each with a stored result of the current
    key). Unchanged when the learner has no ``teacher_from`` or any of those runs is not
    finished in ``out`` (then ``teacher`` stays None and :func:`run_job` refuses the job)."""
    if job.teacher_from is None:
        return job
    records: dict[str, Sequence[bool]] = {}
    for source in jobs(cfg):
        if source.tier == job.tier and source.algo == job.teacher_from:
            stored = _stored_result(out, source, job_key(source, cfg["episodes"], cfg["num_envs"],
                                                         cfg["validation_episodes"]))
            if stored is None or "validation" not in stored["result"]:
                return job
            records[source.name] = stored["result"]["validation"]["captured"]
    return dataclasses.replace(job, teacher=choose_run(records)) if records else job


def _stored_result(out: str | Path, job: Job, key: dict[str, Any]) -> Optional[dict[str, Any]]:
    """The result stored in the job's run folder when its key equals ``key`` and, for a
    fine-tuning, the run it started from is still there unchanged, for a distillation from a
    trained run, that teacher (None otherwise or unreadable)."""
    run = Path(out) / "runs" / job.name
    try:
        stored = json.loads((run / RESULT_FILE).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(stored, dict) or stored.get("key") != json.loads(json.dumps(key)):
        return None
    if not run_state.same_sources(run_state.read_meta(run), _start_folder(out, job), _teacher_folder(out, job)):
        return None
    return stored


def run_job(job: Job, out: str, episodes: int, num_envs: int, num_threads: int = 0,
            validation_episodes: Optional[int] = None) -> dict[str, Any]:
    """Trains ``job`` into ``out/runs/<name>`` and evaluates it: its metrics and episode records
    on the held-out and the validation episodes (``validation_episodes``; None: as many as
    ``episodes``; also ``out/runs/<name>/result.json``).

    Resumable: a job whose run folder holds a result of the same :func:`job_key` is not run again
    (``"reused": true``); a finished training of the same config whose stored evaluation has
    another key (the code or the episodes changed) is evaluated again without retraining; a run interrupted while training (Ctrl+C, a killed process) continues
    from its latest checkpoint (:func:`accd_gym.learning.training.resume`) to the same total; anything
    else starts the run afresh."""

    run = Path(out) / "runs" / job.name
    key = job_key(job, episodes, num_envs, validation_episodes)
    stored = _stored_result(out, job, key)
    if stored is not None:
        return stored["result"] | {"reused": True}
    start = _start_folder(out, job)
    raw = read_json_object(job.train_config, "train_config (training config)")
    raw["env"] = {**(raw.get("env") or {}), "tier": job.tier}  # the recipe's env options (residual, history) stay
    raw["seed"] = job.seed
    raw["total_timesteps"] = job.timesteps
    raw["num_threads"] = num_threads
    if start is not None:  # RL fine-tuning: from the finished run of the same tier and seed
        meta = run_state.read_meta(start)
        if not (isinstance(meta, dict) and meta.get("status") == "done"):
            raise ConfigError(f"{job.name} starts from {job.source}, which is not trained in {out}: run its learner "
                              f"{job.init_from!r} first (`--algos {job.init_from}`)")
        raw["init_from"] = str(start)
    if job.teacher_from is not None:  # a distillation taught by another learner's validation-chosen run
        if job.teacher is None:
            raise ConfigError(f"{job.name} learns from the {job.teacher_from} run of {job.tier} chosen on the validation "
                              f"episodes, and not every {job.teacher_from} run of {job.tier} is finished in {out}: run "
                              f"its learner first (`--algos {job.teacher_from}`)")
        raw["teacher"] = str(_teacher_folder(out, job))
    distilled = distill.is_recipe(raw)  # a distillation recipe (behaviour cloning, DAgger): its own trainer
    updates = raw.get("update_threads", 0)
    # (A value that is not an integer is left for validate_config to refuse, naming it.)
    if not distilled and num_threads > 0 and type(updates) is int and updates > num_threads:
        # A job with a CPU budget (Ray's cpus_per_job) keeps its gradient updates within it.
        raw["update_threads"] = num_threads
    cfg = distill.validate_recipe(raw) if distilled else training.validate_config(raw)
    trained_now = not run_state.trained(run, cfg)
    if not trained_now:  # its evaluation is missing or stale (other code or episodes): not retrained
        meta = json.loads((run / "run.json").read_text())
    elif run_state.continues(run, cfg, distilled=distilled):
        meta = distill.resume(run, make_teacher=_teacher) if distilled else training.resume(run, progress=False)
    else:
        run_state.set_aside(run)  # another recipe's training (or an unsaved one): kept under OUT/superseded
        meta = (distill.train(cfg, run, make_teacher=_teacher) if distilled
                else training.train(cfg, run, progress=False))
    if meta["status"] == "interrupted":  # Ctrl+C: its checkpoint is written; a rerun resumes it
        raise KeyboardInterrupt(f"{job.name}: training interrupted at {meta['timesteps']} steps")
    t1 = time.perf_counter()
    policy = load_policy(str(run))
    record = evaluate_policy(policy, job.tier, episodes, num_envs, num_threads)
    validation = evaluate_policy(policy, job.tier, episodes if validation_episodes is None else validation_episodes,
                                 num_envs, num_threads, validation=True)
    result = {"job": job.__dict__, "name": job.name, "status": meta["status"], "timesteps": meta["timesteps"],
              # The run's own training time (every resumed part, whenever it ran): a run trained
              # by an earlier invocation is only evaluated now (trained_now False).
              "train_wall_s": meta.get("wall_time_s", 0.0), "trained_now": trained_now,
              "eval_wall_s": round(time.perf_counter() - t1, 2),
              "steps_per_s": meta.get("steps_per_s"), "run": str(run), "episodes": record,
              "validation": validation}
    if meta["status"] == "done":
        files.write_text(run / RESULT_FILE, json.dumps({"key": key, "result": result}))
    return result | {"reused": False}


def _teacher(spec: str, seed: int, config: dict) -> Any:
    """A distillation recipe's teacher, resolved as ``accd-gym evaluate --policy`` resolves a policy."""
    return load_policy(spec, seed, config=config)


def _run_jobs(todo: list[Job], cfg: dict[str, Any], out: Path, ray_address: Optional[str],
              progress: Callable[[str], None]) -> list[dict[str, Any]]:
    """Runs the jobs locally or as Ray tasks; returns their results in job order. Jobs that
    depend on another learner's runs (``init_from``, ``teacher_from``) run after every job that
    starts afresh, their teachers chosen then (:func:`with_teacher`)."""
    results: dict[str, dict[str, Any]] = {}

    def run_wave(wave: list[Job]) -> None:
        if wave:
            try:
                results.update(zip((j.name for j in wave), _run_wave(wave, cfg, out, ray_address, progress)))
            except _Interrupted as e:
                raise _Interrupted([results[j.name] for j in todo if j.name in results] + e.results, str(e)) from None

    run_wave([j for j in todo if j.starts_afresh])
    # (the teachers are chosen once the runs they are chosen from are finished)
    run_wave([with_teacher(j, out, cfg) for j in todo if not j.starts_afresh])
    return [results[j.name] for j in todo]


def _run_wave(todo: list[Job], cfg: dict[str, Any], out: Path, ray_address: Optional[str],
              progress: Callable[[str], None]) -> list[dict[str, Any]]:
    """Runs the jobs locally (in order) or as Ray tasks; returns their results in job order."""
    if ray_address is None:
        results = []
        for i, job in enumerate(todo):
            progress(f"[{i + 1}/{len(todo)}] training {job.name} ({job.timesteps} steps)")
            try:
                results.append(run_job(job, str(out), cfg["episodes"], cfg["num_envs"],
                                       validation_episodes=cfg["validation_episodes"]))
            except KeyboardInterrupt as e:
                raise _Interrupted(results, str(e) or "SIGINT") from None
        return results

    ray = distributed.connect(ray_address)
    task = ray.remote(num_cpus=cfg["cpus_per_job"], max_retries=1)(run_job)
    # Longest first, so that the long jobs do not start last: an off-policy learner's job (SAC:
    # measured at 330 steps/s with one thread, a gradient step every 4 env steps) costs several
    # times a PPO job of more steps (3,800 steps/s).
    order = sorted(range(len(todo)), key=lambda i: ("sac" not in todo[i].algo, -todo[i].timesteps, i))
    refs = [task.remote(todo[i], str(out), cfg["episodes"], cfg["num_envs"], cfg["cpus_per_job"],
                            cfg["validation_episodes"]) for i in order]
    done: dict[int, dict[str, Any]] = {}
    pending = dict(zip(refs, order))
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1)
        i = pending.pop(ready[0])
        done[i] = ray.get(ready[0])
        progress(f"[{len(done)}/{len(todo)}] finished {todo[i].name}")
    return [done[i] for i in range(len(todo))]


#: The config a benchmark folder was made with: a rerun into it must have the same.
CONFIG_FILE = "benchmark_config.json"


def _claim(out: Path, config: dict[str, Any]) -> None:
    """Records ``config`` in ``out`` (first run) or refuses a folder made with another one:
    ConfigError naming the folder and the keys that differ. Recipes count by their name and
    bytes (:func:`_portable`): the same recipes from another checkout are the same config, an
    edited recipe is another. A config that only adds learners to the folder's (every other key
    and every learner it had the same) extends the folder: it is recorded, and the runs already
    there stay valid."""
    mine = _portable(config)
    path = out / CONFIG_FILE
    try:
        stored = json.loads(path.read_text())
    except FileNotFoundError:
        files.write_text(path, json.dumps(mine, indent=1))
        return
    except (OSError, ValueError) as e:
        raise ConfigError(f"invalid config: --out {str(out)!r}: its {CONFIG_FILE} is unreadable ({e})") from None
    if _extends(stored, mine):
        files.write_text(path, json.dumps(mine, indent=1))
        return
    if stored != mine:
        keys = sorted(k for k in set(stored) | set(mine) if stored.get(k) != mine.get(k)) if isinstance(stored, dict) else ["*"]
        raise ConfigError(f"invalid config: --out {str(out)!r} was made by another benchmark config (differs in {keys}); "
                          "rerun with that config or choose another --out")


def _extends(stored: Any, mine: dict[str, Any]) -> bool:
    """``mine`` is ``stored`` with learners added (and nothing else changed)."""
    if not isinstance(stored, dict) or stored == mine or not isinstance(stored.get("learners"), dict):
        return False
    same_rest = {k: v for k, v in stored.items() if k != "learners"} == {k: v for k, v in mine.items() if k != "learners"}
    kept = all(mine["learners"].get(k) == v for k, v in stored["learners"].items())
    return same_rest and kept


class _Interrupted(Exception):
    """Ctrl+C during the jobs: the results of the jobs finished before it."""

    def __init__(self, results: list[dict[str, Any]], why: str) -> None:
        super().__init__(why)
        self.results = results


def _run_status(run: Path) -> str:
    """A job that has no result: "not started", or its training's state from its run.json (the
    steps of its latest checkpoint while it trains)."""
    try:
        meta = json.loads((run / "run.json").read_text())
    except (OSError, ValueError):
        return "not started"
    if not isinstance(meta, dict):
        return "not started"
    if meta.get("status") == "done":
        return "trained; its evaluation is missing or stale (a rerun evaluates it)"
    # A run in training records its latest checkpoint's steps (checkpoint_steps); "timesteps"
    # only once it stopped.
    steps = meta.get("timesteps", meta.get("checkpoint_steps"))
    where = "no checkpoint yet" if steps is None else f"at {steps:,}"
    return f"{meta.get('status', 'unfinished')}, {where} of {meta.get('total_timesteps', 0):,} steps"


def _baseline_record(name: str, tier: str, config: dict[str, Any], out: Path,
                     progress: Callable[[str], None]) -> dict[str, Any]:
    """Baseline ``name``'s episode record on the tier's held-out episodes, with its record on the
    validation episodes under ``"validation"``; stored once in ``out/baselines`` and reused while
    its key (baseline, tier configuration, code, episodes, batch) is unchanged."""

    key = json.loads(json.dumps({"baseline": name, "tier_config": _tier(tier).config(), "build": build_digest(),
                                 "episodes": config["episodes"], "validation_episodes": config["validation_episodes"],
                                 "num_envs": config["num_envs"]}))
    path = out / "baselines" / f"{tier}_{name}.json"
    try:
        stored = json.loads(path.read_text())
        if isinstance(stored, dict) and stored.get("key") == key:
            return stored["record"]
    except (OSError, ValueError):
        pass
    progress(f"baseline {name} on {tier}")
    record = evaluate_policy(_baseline_policy(name, tier), tier, config["episodes"], config["num_envs"])
    record["validation"] = evaluate_policy(_baseline_policy(name, tier), tier, config["validation_episodes"],
                                           config["num_envs"], validation=True)
    files.write_text(path, json.dumps({"key": key, "record": record}))
    return record


def _baseline_policy(name: str, tier: str) -> Any:
    """The registered controller ``name`` built for the tier's configuration (the LQR is designed
    on the tier's physics: its base configuration, the nominal draw of a randomized tier)."""
    return load_policy(name, 0, config={"tier": tier})


def iqm(values: Sequence[float]) -> float:
    """Interquartile mean (rliable's: ``scipy.stats.trim_mean(values, 0.25)``)."""
    return _iqm(values)


def stratified_bootstrap(captured: Sequence[Sequence[bool]], *, resamples: int = BOOTSTRAP_RESAMPLES,
                         seed: int = BOOTSTRAP_SEED, level: float = 0.95) -> tuple[float, float]:
    """The 95 % interval of the IQM of the seeds' capture rates by the two-level bootstrap of the
    module docs (seeds, then episodes within each seed). ``captured``: per seed, its episodes."""
    rates = np.array([np.mean(c) for c in captured], dtype=float)
    n = np.array([len(c) for c in captured])
    rng = np.random.default_rng(seed)
    pick = rng.integers(0, rates.size, size=(resamples, rates.size))
    resampled = rng.binomial(n[pick], rates[pick]) / n[pick]
    resampled.sort(axis=1)
    k = int(0.25 * rates.size)
    stats = resampled[:, k:rates.size - k].mean(axis=1)
    a = (1.0 - level) / 2.0
    return float(np.quantile(stats, a)), float(np.quantile(stats, 1.0 - a))


def probability_of_improvement(x: Sequence[float], y: Sequence[float]) -> float:
    """rliable's probability of improvement of X over Y on one task: P(X > Y) over every pair of
    X's and Y's runs, a tie counting one half (the Mann-Whitney U statistic over ``len(x) * len(y)``)."""
    a, b = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if a.size == 0 or b.size == 0:
        raise ValueError(f"probability_of_improvement: needs runs on both sides, got {a.size} and {b.size}")
    gt = (a[:, None] > b[None, :]).sum()
    eq = (a[:, None] == b[None, :]).sum()
    return float((gt + 0.5 * eq) / (a.size * b.size))


#: The criteria of the report's Target section: the largest seed spread of a learned method
#: (rate points) and the significance level of the paired McNemar test.
TARGET_MAX_SPREAD = 0.20
TARGET_ALPHA = 0.05
#: The standalone target's largest seed spread of the chosen standalone method (rate points).
STANDALONE_MAX_SPREAD = 0.10
#: The tiers on which a learned policy is to match or beat the best classical controller: the
#: realistic ones, where the classical controllers miss episodes (on the others the LQR captures
#: all or nearly all, so a learned policy can at best tie it). A config without either scores
#: every tier with learned runs.
TARGET_TIERS = ("precision", "hard")


def target(tiers: dict[str, Any], episodes: dict[str, dict[str, Any]],
           validation: dict[str, dict[str, dict[str, Sequence[bool]]]], *, family: Optional[str] = None) -> Optional[dict[str, Any]]:
    """Whether a learned policy beats the best classical controller, per tier with one and with
    learned runs.

    The reference is the tier's best classical controller (``tiers[tier]["best"]["classical"]``
    from :func:`summarize`, chosen on the validation episodes; the LQR where the numbers name
    none). ``family`` None (the benchmark's target): the chosen learned method of any family
    (:func:`choose_method` on the validation episodes) at least the reference (held-out IQM >= its
    rate, the interval reaching it, the chosen run not significantly worse by the paired exact
    McNemar), significantly better on one scored tier (its chosen run, :func:`choose_run` on the
    validation episodes, p < :data:`TARGET_ALPHA` on the held-out episodes), and every learned
    method's seed spread at most :data:`TARGET_MAX_SPREAD`. ``family="standalone"`` (a network alone
    at run time): only standalone methods compete, and on every scored tier the chosen one must
    capture significantly more than the reference (p < :data:`TARGET_ALPHA`, IQM above its rate),
    at least as many as the chosen hybrid method (IQM), with its seeds within
    :data:`STANDALONE_MAX_SPREAD`.

    ``scored``: the tier is one of :data:`TARGET_TIERS` (every tier when none of them is there).
    ``episodes``: per tier, ``{baseline or run name: captured}`` on the held-out episodes (reported,
    never used to choose); ``validation``: per tier, ``{method: {run name: captured}}`` on the
    validation episodes (what the method and run are chosen by)."""
    standalone = family == "standalone"
    max_spread = STANDALONE_MAX_SPREAD if standalone else TARGET_MAX_SPREAD
    out: dict[str, Any] = {}
    for tier, t in tiers.items():
        rows = t["policies"]
        ref = (t.get("best") or {}).get("classical") or "lqr"
        learned = {k: r for k, r in rows.items()
                   if r["kind"] == "learned" and (family is None or r.get("family", "standalone") == family)}
        if ref not in rows or ref not in episodes.get(tier, {}) or not learned:
            continue
        ref_rate = rows[ref]["rate"]
        chosen = {m: runs for m, runs in validation.get(tier, {}).items() if m in learned and runs}
        if not chosen:
            continue
        best_algo = choose_method(chosen)
        best = learned[best_algo]
        best_run = choose_run(chosen[best_algo])
        a, b = np.asarray(episodes[tier][best_run], dtype=bool), np.asarray(episodes[tier][ref], dtype=bool)
        only_a, only_b = int(np.sum(a & ~b)), int(np.sum(~a & b))
        p = mcnemar_exact(only_a, only_b)
        spreads = {k: max(r["rates"]) - min(r["rates"]) for k, r in learned.items() if not standalone or k == best_algo}
        widest = max(spreads, key=lambda k: (spreads[k], k))
        spread = spreads[widest]
        at_least = (best["iqm"] >= ref_rate and best["ci95"][1] >= ref_rate
                    and not (only_b > only_a and p < TARGET_ALPHA))
        v = {"method": best_algo, "iqm": best["iqm"], "ci95": best["ci95"], "classical": ref, "classical_rate": ref_rate,
             "best_run": best_run, "only_learned": only_a, "only_classical": only_b, "p_value": p,
             "at_least_classical": bool(at_least), "above_classical": bool(best["iqm"] > ref_rate),
             "significantly_better": bool(only_a > only_b and p < TARGET_ALPHA),
             "max_seed_spread": spread, "widest_spread_method": widest, "spread_ok": bool(spread <= max_spread)}
        if standalone:
            hybrid = {m: runs for m, runs in validation.get(tier, {}).items()
                      if runs and rows.get(m, {}).get("kind") == "learned" and rows[m].get("family") == "hybrid"}
            h = choose_method(hybrid) if hybrid else None
            v |= {"hybrid_method": h, "hybrid_iqm": None if h is None else rows[h]["iqm"],
                  "at_least_hybrid": bool(h is None or best["iqm"] >= rows[h]["iqm"])}
        out[tier] = v
    if not out:
        return None
    scored = [t for t in out if t in TARGET_TIERS] or list(out)
    for tier, v in out.items():
        v["scored"] = tier in scored
    if standalone:
        met = all(out[t]["significantly_better"] and out[t]["above_classical"] and out[t]["at_least_hybrid"]
                  and out[t]["spread_ok"] for t in scored)
    else:
        met = (all(out[t]["at_least_classical"] for t in scored) and any(out[t]["significantly_better"] for t in scored)
               and all(v["spread_ok"] for v in out.values()))
    return {"tiers": out, "met": bool(met), "family": family, "max_spread": max_spread}


def _medians(record: dict[str, Any]) -> tuple[float, Optional[float]]:
    return float(np.median(record["min_distance"])), _median(record["capture_time"])


def learner_family(spec: dict[str, Any]) -> str:
    """``"hybrid"`` for a learner whose recipe (any tier's) runs on a residual base (the env option
    ``residual``: at run time the policy corrects a classical controller's command),
    ``"standalone"`` otherwise (a network alone at run time, whatever taught it)."""
    recipes = spec.get("train_config")
    paths = list(recipes.values()) if isinstance(recipes, dict) else [recipes] if recipes else []
    for path in paths:
        env = read_json_object(path, "train_config (training config)").get("env") or {}
        if isinstance(env, dict) and env.get("residual"):
            return "hybrid"
    return "standalone"


def is_classical(name: str) -> bool:
    """A baseline the learned policies are set against (the registry's ``classical`` flag)."""
    return name in CONTROLLERS and CONTROLLERS[name].classical


#: The learner families of the report's summary, in its column order.
FAMILIES = ("hybrid", "standalone")


def summarize(cfg: dict[str, Any], results: list[dict[str, Any]], baselines: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """The report's numbers per tier: learned algorithms (family, IQM, interval, per-seed rates,
    the run chosen on the validation episodes), baselines (rate, Wilson interval), medians; the
    best classical controller, the best hybrid and the best standalone learned method, each chosen
    on the validation episodes (``best``); every learned method relative to that classical
    controller; and the McNemar comparison of the learned run and the classical baseline chosen on
    the validation episodes (:func:`choose_run`), on the held-out episodes."""
    tiers: dict[str, Any] = {}
    for tier in cfg["tiers"]:
        rows: dict[str, Any] = {}
        runs = [r for r in results if r["job"]["tier"] == tier]
        by_method: dict[str, dict[str, Sequence[bool]]] = {}
        for algo in cfg["learners"]:
            mine = sorted((r for r in runs if r["job"]["algo"] == algo), key=lambda r: r["job"]["seed"])
            if not mine:
                continue
            caps = [r["episodes"]["captured"] for r in mine]
            rates = [float(np.mean(c)) for c in caps]
            lo, hi = stratified_bootstrap(caps)
            pooled = {k: sum((r["episodes"][k] for r in mine), []) for k in ("min_distance", "capture_time")}
            miss, ttc = _medians(pooled)
            by_method[algo] = {r["name"]: r["validation"]["captured"] for r in mine}
            rows[algo] = {"kind": "learned", "family": learner_family(cfg["learners"][algo]),
                          "failures": failures([r["episodes"] for r in mine]),
                          "chosen_run": choose_run(by_method[algo]),
                          "validation_rates": [validation_rate(r["validation"]["captured"]) for r in mine],
                          "seeds": [r["job"]["seed"] for r in mine], "rates": rates,
                          "iqm": iqm(rates), "ci95": [lo, hi], "miss_median_m": miss, "capture_time_median_s": ttc,
                          "train_wall_s": [r["train_wall_s"] for r in mine], "steps_per_s": [r["steps_per_s"] for r in mine]}
        for name, rec in baselines.get(tier, {}).items():
            if rec is None:
                continue
            k, n = int(sum(rec["captured"])), len(rec["captured"])
            miss, ttc = _medians(rec)
            rows[name] = {"kind": "classical" if is_classical(name) else "trivial", "rate": k / n,
                          "validation_rate": validation_rate(rec["validation"]["captured"]),
                          "failures": failures([rec]),
                          "ci95": list(wilson_interval(k, n)), "miss_median_m": miss, "capture_time_median_s": ttc}
        classical = [b for b, row in rows.items() if row["kind"] == "classical"]
        # Every choice on the validation episodes; reported on the held-out ones.
        best_classical = (choose_run({b: baselines[tier][b]["validation"]["captured"] for b in classical})
                          if classical else None)
        best = {"classical": best_classical}
        for family in FAMILIES:
            mine = {m: v for m, v in by_method.items() if rows[m]["family"] == family}
            best[family] = choose_method(mine) if mine else None
        if best_classical is not None:  # the learned methods relative to the best classical controller
            ref = rows[best_classical]["rate"]
            for row in rows.values():
                if row["kind"] == "learned":
                    row["vs_classical"] = None if ref == 0 else [row["iqm"] / ref, row["ci95"][0] / ref, row["ci95"][1] / ref]
                    row["p_improvement_over_classical"] = probability_of_improvement(row["rates"], [ref])
        comparison = None
        if runs and best_classical is not None:
            by_name = {r["name"]: r for r in runs}
            chosen = by_name[choose_run({r["name"]: r["validation"]["captured"] for r in runs})]
            a = np.asarray(chosen["episodes"]["captured"])
            b = np.asarray(baselines[tier][best_classical]["captured"])
            only_a, only_b = int(np.sum(a & ~b)), int(np.sum(~a & b))
            comparison = {"learned": chosen["name"], "learned_rate": float(np.mean(a)), "classical": best_classical,
                          "classical_rate": rows[best_classical]["rate"],
                          "learned_validation_rate": validation_rate(chosen["validation"]["captured"]),
                          "classical_validation_rate": rows[best_classical]["validation_rate"],
                          "both": int(np.sum(a & b)), "only_learned": only_a, "only_classical": only_b,
                          "neither": int(np.sum(~a & ~b)), "p_value": mcnemar_exact(only_a, only_b)}
        tiers[tier] = {"policies": rows, "best": best, "mcnemar": comparison}
    return tiers


def performance_profile(results: list[dict[str, Any]], baselines: dict[str, dict[str, Any]],
                        taus: np.ndarray) -> dict[str, list[float]]:
    """Per policy, the fraction of its runs (every tier and seed) whose capture rate is at least
    each tau (rliable's performance profile on the run scores)."""
    scores: dict[str, list[float]] = {}
    for r in results:
        scores.setdefault(method_label(r["job"]["algo"]), []).append(float(np.mean(r["episodes"]["captured"])))
    for tier_runs in baselines.values():
        for name, rec in tier_runs.items():
            if rec is not None:
                scores.setdefault(name, []).append(float(np.mean(rec["captured"])))
    return {name: [float(np.mean(np.asarray(s) >= t)) for t in taus] for name, s in scores.items()}


def plot_profile(profile: dict[str, list[float]], taus: np.ndarray, path: Path) -> None:
    """The performance profile as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=100)
    for name, frac in profile.items():
        ax.step(taus, frac, where="post", label=name)
    ax.set_xlabel("capture rate threshold tau")
    ax.set_ylabel("fraction of runs (tiers x seeds) with rate >= tau")
    ax.set_ylim(-0.02, 1.02)
    ax.grid(alpha=0.3)
    ax.legend()
    ax.set_title("Performance profile over every tier")
    fig.tight_layout()

    save_figure(fig, path)
    plt.close(fig)


def _pct(x: float) -> str:
    return f"{100 * x:.1f} %"


_ALGORITHM_WORDS = frozenset({"ppo", "sac", "tqc", "td3", "a2c", "ddpg", "dqn", "trpo", "crossq", "bc"})
_SPELLED = {"dagger": "DAgger"}


def method_label(algo: str) -> str:
    """A learner's name as the report prints it: ``residual_sac`` -> ``residual SAC``, ``ppo`` ->
    ``PPO``, ``dagger_ppo`` -> ``DAgger PPO``."""
    return " ".join(_SPELLED.get(w, w.upper() if w in _ALGORITHM_WORDS else w) for w in algo.split("_"))


def _reuse_note(doc: dict[str, Any]) -> str:
    """The header's account of the work done by earlier invocations into the same folder: jobs
    reused whole (training and evaluation) and runs trained then and evaluated now."""
    runs = doc["runs"]
    reused = [r for r in runs if r.get("reused")]
    earlier = [r for r in runs if not r.get("reused") and not r.get("trained_now", True)]
    note = ""
    if reused:
        minutes = sum(r["train_wall_s"] + r["eval_wall_s"] for r in reused) / 60
        note += (f"; {len(reused)} of {len(runs)} jobs were finished by an earlier invocation into the same folder "
                 f"and reused (their training and evaluation took {minutes:.1f} min then)")
    if earlier:
        minutes = sum(r["train_wall_s"] for r in earlier) / 60
        note += (f"; {len(earlier)} of {len(runs)} runs were trained by an earlier invocation into the same folder "
                 f"({minutes:.1f} min of training, summed over the runs) and evaluated now")
    return note


def _target_markdown(t: Optional[dict[str, Any]]) -> list[str]:
    """A Target section from :func:`target`'s numbers (nothing without them): the benchmark's
    target (any learned method) or the standalone one (``t["family"]``)."""
    if not t:
        return []
    standalone = t.get("family") == "standalone"
    scored = [tier for tier, v in t["tiers"].items() if v["scored"]]
    where = f"On the {' and '.join(scored)} tier{'s' if len(scored) > 1 else ''}"
    spread = f"{100 * t.get('max_spread', TARGET_MAX_SPREAD):.0f} points"
    if standalone:
        lines = ["", "## Target: a standalone learned policy", "",
                 f"{where} a standalone learned policy (a network alone at run time) captures significantly more "
                 "held-out episodes than the best classical controller (its chosen run by the paired exact McNemar, "
                 f"p < {TARGET_ALPHA}, and the IQM of its seeds above the controller's rate), at least as many as the "
                 f"best hybrid (residual) method (IQM), with its seeds within {spread}."]
    else:
        lines = ["", "## Target", "",
                 f"{where} a learned policy captures at least as many held-out episodes as the best classical "
                 "controller (IQM >= its rate, the interval reaching it, the chosen run not significantly worse by the "
                 "paired exact McNemar), significantly more on at least one of them "
                 f"(p < {TARGET_ALPHA}), and no learned method's seeds spread by more than {spread} on any tier."]
    lines[-1] += (" Tiers outside the target show their numbers with `-` for the criteria that do not apply to them. "
                  "The method and its run, and the classical controller, are chosen on the validation episodes (a "
                  "method by the IQM of its runs' validation rates, a run or controller by its validation rate); the "
                  "held-out episodes only report.")
    head = ("| tier | chosen method (held-out IQM) | best classical | chosen run: only learned / only classical, p | "
            + ("significantly more, IQM above | best hybrid (IQM) | at least the hybrid | seed spread |"
               if standalone else "at least the classical | significantly more | largest seed spread (method) |"))
    lines += ["", head, "|" + "---|" * head.count(" | ") + "---|"]
    yes = {True: "yes", False: "no"}
    for tier, v in t["tiers"].items():
        row = (f"| {tier} | {method_label(v['method'])} {_pct(v['iqm'])} ({_pct(v['ci95'][0])} - {_pct(v['ci95'][1])}) "
               f"| {v['classical']} {_pct(v['classical_rate'])} | `{v['best_run']}`: {v['only_learned']} / "
               f"{v['only_classical']}, p = {v['p_value']:.3g} ")
        if standalone:
            hybrid = "-" if v["hybrid_method"] is None else f"{method_label(v['hybrid_method'])} {_pct(v['hybrid_iqm'])}"
            more = yes[v["significantly_better"] and v["above_classical"]] if v["scored"] else "-"
            row += (f"| {more} | {hybrid} | {yes[v['at_least_hybrid']] if v['scored'] else '-'} "
                    f"| {100 * v['max_seed_spread']:.1f} points ({yes[v['spread_ok']]}) |")
        else:
            at_least, better = ((yes[v["at_least_classical"]], yes[v["significantly_better"]]) if v["scored"]
                                else ("-", "-"))
            row += (f"| {at_least} | {better} | {100 * v['max_seed_spread']:.1f} points, "
                    f"{method_label(v['widest_spread_method'])} ({yes[v['spread_ok']]}) |")
        lines.append(row)
    lines += ["", f"Target {'met' if t['met'] else 'not met'} on these runs" + ("." if t["met"] else ":")]
    if not t["met"]:
        lines += [""] + [f"- {reason}" for reason in _target_misses(t)]
    return lines


def _target_misses(t: dict[str, Any]) -> list[str]:
    """The criteria a :func:`target` verdict misses, with the numbers by which it misses them."""
    out = []
    standalone = t.get("family") == "standalone"
    limit = t.get("max_spread", TARGET_MAX_SPREAD)
    for tier, v in t["tiers"].items():
        against = (f"its chosen run {v['only_learned']} / {v['only_classical']} episodes against the "
                   f"{v['classical']}, p = {v['p_value']:.3g}")
        if v["scored"] and not standalone and not v["at_least_classical"]:
            out.append(f"{tier}: the chosen method, {method_label(v['method'])}, captures {_pct(v['iqm'])} (IQM, "
                       f"interval up to {_pct(v['ci95'][1])}) against the {v['classical']}'s {_pct(v['classical_rate'])}; "
                       f"{against}.")
        if v["scored"] and standalone and not (v["significantly_better"] and v["above_classical"]):
            out.append(f"{tier}: the chosen standalone method, {method_label(v['method'])}, captures {_pct(v['iqm'])} "
                       f"(IQM, {_pct(v['ci95'][0])} - {_pct(v['ci95'][1])}) against the {v['classical']}'s "
                       f"{_pct(v['classical_rate'])}; {against}.")
        if v["scored"] and standalone and not v["at_least_hybrid"]:
            out.append(f"{tier}: {method_label(v['method'])}'s IQM {_pct(v['iqm'])} is below the best hybrid method, "
                       f"{method_label(v['hybrid_method'])}, at {_pct(v['hybrid_iqm'])}.")
        if not v["spread_ok"] and (v["scored"] or not standalone):
            out.append(f"{tier}: {method_label(v['widest_spread_method'])}'s seeds spread by "
                       f"{100 * v['max_seed_spread']:.1f} points, {100 * (v['max_seed_spread'] - limit):.1f} "
                       f"more than the {100 * limit:.0f} allowed.")
    scored = {tier: v for tier, v in t["tiers"].items() if v["scored"]}
    if not standalone and not any(v["significantly_better"] for v in scored.values()):
        best = min(scored.items(), key=lambda kv: kv[1]["p_value"])
        out.append(f"no tier's chosen run captures significantly more than the best classical controller (smallest p: "
                   f"{best[0]}, {best[1]['p_value']:.3g}).")
    return out


def _summary_markdown(doc: dict[str, Any]) -> list[str]:
    """The report's summary: per tier the best classical controller, the best hybrid and the best
    standalone learned method (each chosen on the validation episodes) on the held-out episodes,
    and the standalone method relative to the classical controller."""
    rows = []
    for tier, t in doc["tiers"].items():
        best = t.get("best") or {}
        cells = []
        c = best.get("classical")
        cells.append("-" if c is None else f"{c} {_pct(t['policies'][c]['rate'])} ({_pct(t['policies'][c]['ci95'][0])} - "
                     f"{_pct(t['policies'][c]['ci95'][1])})")
        for family in FAMILIES:
            m = best.get(family)
            row = None if m is None else t["policies"][m]
            cells.append("-" if row is None else f"{method_label(m)} {_pct(row['iqm'])} ({_pct(row['ci95'][0])} - "
                         f"{_pct(row['ci95'][1])})")
        m = best.get("standalone")
        rel = None if m is None else t["policies"][m].get("vs_classical")
        cells.append("-" if rel is None else f"{rel[0]:.3f} ({rel[1]:.3f} - {rel[2]:.3f})")
        rows.append(f"| {tier} | " + " | ".join(cells) + " |")
    if not rows:
        return []
    return ["", "## Summary", "",
            "Per tier, on the held-out episodes: the best classical controller, the best hybrid method (a learned "
            "correction of a classical controller's command) and the best standalone learned method (a network alone "
            "at run time), each chosen on the validation episodes, with its 95 % interval (learned: IQM of the seeds); "
            "the standalone method's IQM and interval divided by the classical controller's rate.", "",
            "| tier | best classical | best hybrid (IQM) | best standalone (IQM) | standalone / classical |",
            "|---|---|---|---|---|", *rows]


#: The README's results table lies between these two lines (``accd-gym benchmark --readme``).
README_BEGIN = "<!-- begin benchmark table (accd-gym benchmark --readme README.md) -->"
README_END = "<!-- end benchmark table -->"


def readme_table(doc: dict[str, Any]) -> str:
    """The README's results table from a benchmark report document: per tier every classical
    controller's rate, the best hybrid and the best standalone method (IQM, chosen on the
    validation episodes), the trivial references' rates."""
    first = next(iter(doc["tiers"].values()), {}).get("policies", {})
    classical = [n for n, r in first.items() if r["kind"] == "classical"]
    trivial = [n for n, r in first.items() if r["kind"] == "trivial"]
    learned = {m for t in doc["tiers"].values() for m, r in t["policies"].items() if r["kind"] == "learned"}
    seeds = {len(r["rates"]) for t in doc["tiers"].values() for r in t["policies"].values() if r["kind"] == "learned"}
    n_seeds = f"IQM of {seeds.pop()} seeds" if len(seeds) == 1 else "IQM of the seeds"
    cols = [*classical, *(FAMILIES if learned else ()), *trivial]
    label = lambda c: (CONTROLLERS[c].summary.split(",")[0] if c in CONTROLLERS else c) + f" (`{c}`)"  # noqa: E731
    head = ["tier", *(label(c) for c in classical), *((f"best hybrid, {n_seeds}", f"best standalone, {n_seeds}")
                                                      if learned else ()), *(label(c) for c in trivial)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for tier, t in doc["tiers"].items():
        cells = [tier]
        for c in cols:
            if c in FAMILIES:
                m = (t.get("best") or {}).get(c)
                cells.append("-" if m is None else f"{_pct(t['policies'][m]['iqm'])} ({method_label(m)})")
            else:
                row = t["policies"].get(c)
                cells.append("-" if row is None else _pct(row["rate"]))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_readme_table(path: str | Path, doc: Optional[dict[str, Any]]) -> None:
    """Replaces the table between :data:`README_BEGIN` and :data:`README_END` in ``path`` with
    :func:`readme_table`; ConfigError naming the file when it cannot be read or has not exactly
    one such block. ``doc`` None only checks the file."""
    try:
        text = Path(path).read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise ConfigError(f"invalid config: --readme {path} cannot be read ({e.__class__.__name__})") from None
    if text.count(README_BEGIN) != 1 or text.count(README_END) != 1 or text.index(README_BEGIN) > text.index(README_END):
        raise ConfigError(f"invalid config: --readme {path} has no block between {README_BEGIN!r} and {README_END!r}, "
                          "or more than one (it needs exactly one)")
    if doc is None:
        return
    head, rest = text.split(README_BEGIN)
    _, tail = rest.split(README_END)
    files.write_text(path, head + README_BEGIN + "\n" + readme_table(doc) + "\n" + README_END + tail)


def report_markdown(doc: dict[str, Any]) -> str:
    """The benchmark report (docs/benchmark.md)."""
    cfg = doc["config"]
    learners = ", ".join(f"{method_label(a)} {len(s['seeds'])} seeds x {s['timesteps']:,} steps"
                         + (f" (tiers {', '.join(s['tiers'])})" if s["tiers"] else "") for a, s in cfg["learners"].items())
    learned = (f"Learned: {learners}, trained on training wake seeds only. Capture rate of a learned algorithm: the IQM "
               "over seeds with a 95 % two-level stratified bootstrap interval (seeds, then episodes); of a baseline: "
               if learners else f"No learned policies in this run (`{Path(cfg.get('source', '')).name or 'config'}`: baselines "
               "only). Capture rate of a baseline: ")
    lines = [
        "# accd-gym benchmark",
        "",
        f"Generated by `{doc['command']}` on {doc['date']} ({doc['machine']}); wall time {doc['wall_time_s'] / 60:.1f} min "
        f"(training and evaluation jobs {doc['jobs_wall_s'] / 60:.1f} min, baselines {doc['baseline_wall_s'] / 60:.1f} min)"
        + _reuse_note(doc) + ".",
        "",
        f"Every policy of a tier meets the same {cfg['episodes']} held-out episodes (episode k: seed 20240607 + k, "
        f"held-out wake seed k). {learned}the rate with its Wilson 95 % interval. Miss distance: the smallest "
        "capture-point-to-boom distance of the episode; time to capture over captured episodes only.",
        "",
        f"Every choice is made on {cfg.get('validation_episodes', cfg['episodes'])} validation episodes per tier "
        "(episode k: seed 7340033 + k, validation wake seed k, a training wake seed that training never draws): "
        "each method's chosen run (the one a shipped policy is), the best learned method, run and classical "
        "baseline that the McNemar tests and the Target section compare. The held-out episodes only report.",
    ]
    lines += _summary_markdown(doc)
    for tier, t in doc["tiers"].items():
        lines += ["", f"## {tier} (`{TIERS[tier].id}`)", "", TIERS[tier].summary + ".", "",
                  "| policy | capture rate | 95 % interval | per seed | miss median (m) | time to capture median (s) |",
                  "|---|---|---|---|---|---|"]
        for name, row in t["policies"].items():
            lo, hi = row["ci95"]
            ttc = "-" if row["capture_time_median_s"] is None else f"{row['capture_time_median_s']:.1f}"
            if row["kind"] == "learned":
                seeds = ", ".join(_pct(r) for r in row["rates"])
                lines.append(f"| {method_label(name)} ({row.get('family', 'standalone')}, IQM of {len(row['rates'])}) "
                             f"| {_pct(row['iqm'])} | {_pct(lo)} - {_pct(hi)} "
                             f"| {seeds} | {row['miss_median_m']:.2f} | {ttc} |")
            else:
                lines.append(f"| {name} | {_pct(row['rate'])} | {_pct(lo)} - {_pct(hi)} | - | {row['miss_median_m']:.2f} | {ttc} |")
        fails = [(n, r["failures"]) for n, r in t["policies"].items() if r.get("failures")]
        if fails:
            f2 = lambda x: "-" if x is None else f"{x:.2f}"  # noqa: E731
            lines += ["", "Failures (learned: pooled over the seeds): the missed episodes, their outcomes, median miss "
                      "distance and closing speed at the closest approach; the captured episodes' median closing speed "
                      "at capture and time to capture.", "",
                      "| policy | missed | outcomes of the missed | miss median (m) | closing speed at closest approach "
                      "(m/s) | closing speed at capture (m/s) | time to capture (s) |", "|---|---|---|---|---|---|---|"]
            lines += [f"| {method_label(n) if t['policies'][n]['kind'] == 'learned' else n} | {f['missed']}/{f['episodes']} "
                      f"| {', '.join(f'{k} {v}' for k, v in sorted(f['outcomes'].items())) or '-'} "
                      f"| {f2(f['missed_miss_median_m'])} | {f2(f['missed_closest_speed_median_mps'])} "
                      f"| {f2(f['capture_speed_median_mps'])} | {f2(f['capture_time_median_s'])} |" for n, f in fails]
        rel = [(n, r) for n, r in t["policies"].items() if r.get("vs_classical")]
        if rel:
            ref = t["best"]["classical"]
            lines += ["", f"Relative to the best classical controller, `{ref}` (chosen on the validation episodes; "
                      f"`{ref}` = 1.0: IQM and interval divided by its rate) and rliable's probability of improvement "
                      f"P(seed's rate > `{ref}`'s, ties one half, averaged over the seeds):", "",
                      f"| policy | family | normalized IQM | 95 % interval | P(improvement over `{ref}`) |",
                      "|---|---|---|---|---|"]
            lines += [f"| {method_label(n)} | {r.get('family', 'standalone')} | {r['vs_classical'][0]:.3f} "
                      f"| {r['vs_classical'][1]:.3f} - {r['vs_classical'][2]:.3f} "
                      f"| {r['p_improvement_over_classical']:.2f} |" for n, r in rel]
        m = t["mcnemar"]
        if m:
            lines += ["", f"Learned run `{m['learned']}` ({_pct(m['learned_rate'])}) vs classical `{m['classical']}` "
                      f"({_pct(m['classical_rate'])}), both chosen as the best on the validation episodes "
                      f"({_pct(m['learned_validation_rate'])} and {_pct(m['classical_validation_rate'])} there), paired "
                      f"on the held-out episodes: both {m['both']}, learned only {m['only_learned']}, classical only "
                      f"{m['only_classical']}, neither {m['neither']}; exact McNemar p = {m['p_value']:.3g}."]
    if doc.get("missing"):
        lines += ["", "## Missing / unfinished runs", "",
                  f"{len(doc['missing'])} of {len(doc['missing']) + len(doc['runs'])} training runs have no result "
                  "in this report; `accd-gym benchmark` into the same folder runs or resumes them.", "",
                  "| run | status |", "|---|---|"]
        lines += [f"| `{m['name']}` | {m['status']} |" for m in doc["missing"]]
    lines += _target_markdown(doc.get("target"))
    lines += _target_markdown(doc.get("standalone_target"))
    lines += ["", "## Performance profile", "", "![performance profile](figures/benchmark_profile.png)", "",
              "Fraction of each policy's runs (every tier; learned: every seed) whose capture rate is at least tau."]
    return "\n".join(lines) + "\n"


def run(config: dict[str, Any], out: str | Path, *, ray_address: Optional[str] = None, docs: Optional[Path] = None,
        command: str = "accd-gym benchmark", progress: Callable[[str], None] = print,
        chosen: Optional[Callable[[Job], bool]] = None, readme: Optional[Path] = None) -> dict[str, Any]:
    """Runs the benchmark of a validated config into ``out``; returns the report document
    (also ``out/benchmark.json``, ``out/benchmark.md``, ``out/performance_profile.png``; with
    ``docs``, docs/benchmark.md and docs/figures/benchmark_profile.png there too).

    ``chosen`` (:func:`selection`): run only those jobs; the report covers every job of the
    config finished in ``out`` (now or by an earlier invocation) and lists the others under
    "Missing / unfinished runs". Ctrl+C while training: the run under way writes its checkpoint,
    the report is written from what is finished and the document's ``interrupted`` says why."""
    import datetime

    # before the jobs: a read-only folder (or --docs folder) is refused at once
    out = files.writable_folder(Path(out).resolve(), "--out",
                                ("benchmark.json", "benchmark.md", "episodes.json", "performance_profile.png"))
    if docs is not None:
        files.writable_folder(docs, "--docs", ("benchmark.md",))
        files.writable_folder(docs / "figures", "--docs", ("benchmark_profile.png",))
    if readme is not None:  # its table's block is checked before any work
        write_readme_table(readme, None)
    _claim(out, config)
    t0 = time.perf_counter()
    every = jobs(config)
    todo = [j for j in every if chosen is None or chosen(j)]
    interrupted = None
    try:
        ran = _run_jobs(todo, config, out, ray_address, progress)
    except _Interrupted as e:
        ran, interrupted = e.results, str(e)
        progress(f"interrupted ({interrupted}); the report is written from the finished runs")
    by_name = {r["name"]: r for r in ran if r.get("status") == "done"}
    results, missing = [], []
    for job in every:  # the report covers every finished run in OUT, chosen now or earlier
        if job.name not in by_name:
            job = with_teacher(job, out, config)
            stored = _stored_result(out, job, job_key(job, config["episodes"], config["num_envs"],
                                                      config["validation_episodes"]))
            if stored is not None:
                by_name[job.name] = stored["result"] | {"reused": True}
        if job.name in by_name:
            results.append(by_name[job.name])
        else:
            missing.append({"name": job.name, "status": _run_status(out / "runs" / job.name)})
    jobs_s = time.perf_counter() - t0
    t1 = time.perf_counter()
    baselines: dict[str, dict[str, Any]] = {}
    for tier in config["tiers"]:
        baselines[tier] = {}
        for name in config["baselines"]:
            baselines[tier][name] = _baseline_record(name, tier, config, out, progress)
    baseline_s = time.perf_counter() - t1
    taus = np.linspace(0.0, 1.0, 101)
    profile = performance_profile(results, baselines, taus)
    summary = summarize(config, results, baselines)
    # The targets' records: held-out (reported) and validation (choosing) episodes per tier.
    held_out = {tier: {**{b: rec["captured"] for b, rec in baselines[tier].items() if rec is not None and is_classical(b)},
                       **{r["name"]: r["episodes"]["captured"] for r in results if r["job"]["tier"] == tier}}
                for tier in config["tiers"]}
    valid = {tier: {algo: {r["name"]: r["validation"]["captured"] for r in results
                           if r["job"]["tier"] == tier and r["job"]["algo"] == algo} for algo in config["learners"]}
             for tier in config["tiers"]}
    doc = {
        "command": command,
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "machine": _machine(),
        "config": config,
        "wall_time_s": time.perf_counter() - t0,
        "jobs_wall_s": jobs_s,  # this invocation's jobs (training and evaluation); a run's own training: its train_wall_s
        "baseline_wall_s": baseline_s,
        "tiers": summary,
        "target": target(summary, held_out, valid),
        "standalone_target": target(summary, held_out, valid, family="standalone"),
        "runs": [{k: v for k, v in r.items() if k != "episodes"} | {"capture_rate": float(np.mean(r["episodes"]["captured"]))}
                 for r in results],
        "profile": {"tau": taus.tolist(), **profile},
        "missing": missing,
        "interrupted": interrupted,
    }
    files.write_text(out / "benchmark.json", json.dumps(doc, indent=1))
    files.write_text(out / "episodes.json", json.dumps({"runs": {r["name"]: r["episodes"] for r in results},
                                                        "baselines": baselines}))
    files.write_text(out / "benchmark.md", report_markdown(doc).replace("figures/benchmark_profile.png", "performance_profile.png"))
    plot_profile(profile, taus, out / "performance_profile.png")
    if docs is not None:
        files.write_text(docs / "benchmark.md", report_markdown(doc))
        plot_profile(profile, taus, docs / "figures" / "benchmark_profile.png")
    if readme is not None:
        write_readme_table(readme, doc)
    return doc


def _machine() -> str:
    """The machine a report comes from: architecture, CPU model, CPU count, Python, and the
    kernels the loaded BLAS libraries chose for this CPU (a record of the machine: the
    environment and the LQR run on none of them)."""
    model = platform.processor()
    try:
        with open("/proc/cpuinfo") as f:
            model = next((line.split(":", 1)[1].strip() for line in f if line.startswith("model name")), model)
    except OSError:
        pass

    blas = sorted({f"{api} {arch}".strip() for api, arch in blas_kernels()})
    return (f"{platform.machine()}{f' {model}' if model else ''}, {_cpus()} CPUs, Python {platform.python_version()}"
            + (f", BLAS kernels {' / '.join(blas)}" if blas else ""))


def _cpus() -> int:
    import os

    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


__all__ = ["DEFAULTS", "RESULT_FILE", "Job", "choose_method", "choose_run", "chosen_run", "validation_rate", "build_digest", "job_key", "jobs", "load_config", "validate_config", "run", "run_job", "evaluate_policy",
           "stratified_bootstrap", "summarize", "performance_profile", "report_markdown", "iqm",
           "probability_of_improvement", "target", "selection", "CONFIG_FILE", "failures", "TARGET_MAX_SPREAD", "TARGET_ALPHA"]

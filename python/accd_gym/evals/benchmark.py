"""The benchmark suite (``accd-gym benchmark``): every tier (:mod:`accd_gym.envs.tiers`), learned policies
trained with several seeds, every baseline, the same held-out episodes, one report.

``accd-gym benchmark --config training/benchmark.json --out runs/benchmark`` calls :func:`run`:

1. **Training** (one job per tier, algorithm and seed): the algorithm's training recipe
   (``train_config``, e.g. training/ppo.json) with the tier as its env and the job's seed, trained
   for ``timesteps`` on training wake seeds, then evaluated on the tier's first ``episodes``
   held-out episodes (episode k: seed 20240607 + k, held-out wake seed k, so every policy of a
   tier meets the same episodes). Jobs run one after the other in this process, or, with
   ``--ray ADDRESS`` (``"local"``, ``"auto"``, ``HOST:PORT``), as Ray tasks of ``cpus_per_job``
   CPUs each, placed wherever the cluster has room (the same machinery as ``evaluate --ray``),
   the longest first. Resumable: a finished job's result stays in ``OUT/runs/<job>/result.json``
   and a rerun into the same ``OUT`` reuses it while its key (:func:`job_key`: job, training
   config, tier, build, evaluation) is unchanged; an interrupted training continues from its
   checkpoint (:func:`run_job`).
2. **Baselines** (``zero``, ``random``, ``guidance``, ``lqr``) on the same episodes of every
   tier; the LQR is designed for each tier's configuration.
3. **Report** (``OUT/benchmark.json``, ``OUT/benchmark.md``, ``OUT/performance_profile.png``):
   per tier and policy the capture rate (learned: the interquartile mean over seeds with a 95 %
   stratified bootstrap interval, and every seed's rate; baselines: the rate with its Wilson
   interval), the median miss distance and time to capture, and the paired exact McNemar test
   (:func:`accd_gym.evals.evaluation.mcnemar_exact`) of the best learned run against the best
   classical baseline on the same episodes; a performance profile over every (tier, seed) run.
   ``--docs`` also writes the report to docs/benchmark.md and the plot to docs/figures/.

**Statistics.** IQM: the mean of the middle half of the seeds' rates (rliable's IQM,
``scipy.stats.trim_mean(x, 0.25)``). Interval: a two-level bootstrap stratified by seed: resample
the seeds with replacement, then each resampled seed's episodes with replacement (drawn exactly as
``Binomial(n, rate) / n``), IQM of the resampled rates; 10,000 resamples, percentile interval, a
fixed generator seed. "Best" learned run and classical baseline are chosen by their rate on the
reported episodes themselves, so the McNemar p-value is that of a comparison picked after the
fact (stated in the report).

Config (JSON object, every key optional; ``quick`` holds the overrides ``--quick`` applies):

================ ===================================================================================
key              meaning
================ ===================================================================================
tiers            tier names (default: all)
learners         ``{"ppo": {"train_config", "seeds", "timesteps", "tiers"}, "sac": {...}}``;
                 ``tiers`` limits an algorithm to some tiers (default: all)
baselines        baseline names (default ``["zero", "random", "guidance", "lqr"]``; unknown ones
                 are refused)
episodes         held-out episodes per tier (default 500)
num_envs         evaluation batch (default 16)
cpus_per_job     CPUs a Ray job reserves, also the threads stepping its envs and at most those of
                 PyTorch in its gradient updates (default 1)
quick            overrides for ``--quick``
================ ===================================================================================
"""

from __future__ import annotations

import copy
import functools
import json
import platform
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

import numpy as np

from accd_gym.errors import ConfigError

#: Defaults of a benchmark config.
DEFAULTS: dict[str, Any] = {
    "tiers": None,
    "learners": {
        "ppo": {"train_config": "training/ppo.json", "seeds": [0, 1, 2, 3, 4], "timesteps": 1_000_000, "tiers": None},
    },
    "baselines": ["zero", "random", "guidance", "lqr"],
    "episodes": 500,
    "num_envs": 16,
    "cpus_per_job": 1,
    "quick": {},
}
#: Bootstrap resamples and the seed of their generator.
BOOTSTRAP_RESAMPLES = 10_000
BOOTSTRAP_SEED = 0
#: Baselines that exist whatever is installed, and the optional ones.
_BASELINES = ("zero", "random", "guidance", "lqr")
_LEARNER_KEYS = ("train_config", "seeds", "timesteps", "tiers")


def validate_config(raw: Any, *, quick: bool = False, root: Optional[Path] = None) -> dict[str, Any]:
    """A complete benchmark config: ``raw`` over :data:`DEFAULTS` (with ``--quick``, its
    ``quick`` overrides on top), every key checked; ConfigError naming the key otherwise.
    Relative ``train_config`` paths are resolved against ``root`` (the config file's folder's
    parent, the repository, by default the working directory)."""
    from accd_gym.envs.tiers import TIERS, merge

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
        if "learners" in q:
            cfg["learners"] = merge(raw.get("learners", DEFAULTS["learners"]), q["learners"])
    tiers = cfg["tiers"] if cfg["tiers"] is not None else list(TIERS)
    bad = [t for t in tiers if t not in TIERS]
    if bad or not tiers:
        raise ConfigError(f"invalid config: `tiers` = {cfg['tiers']!r} is outside the allowed values: a non-empty list of {list(TIERS)}")
    cfg["tiers"] = list(tiers)
    if not isinstance(cfg["learners"], dict):
        raise ConfigError("invalid config: `learners` must be an object {algo: {train_config, seeds, timesteps, tiers}}")
    base = root or Path.cwd()
    for algo, spec in cfg["learners"].items():
        if algo not in ("ppo", "sac"):
            raise ConfigError(f"invalid config: `learners.{algo}` is outside the allowed algorithms: ppo, sac")
        if not isinstance(spec, dict) or set(spec) - set(_LEARNER_KEYS):
            raise ConfigError(f"invalid config: `learners.{algo}` must be an object with keys {list(_LEARNER_KEYS)}")
        spec.setdefault("tiers", None)
        seeds = spec.get("seeds")
        if not isinstance(seeds, list) or not seeds or not all(isinstance(s, int) and s >= 0 for s in seeds):
            raise ConfigError(f"invalid config: `learners.{algo}.seeds` = {seeds!r} is outside the allowed range: a non-empty list of ints >= 0")
        if len(set(seeds)) != len(seeds):
            raise ConfigError(f"invalid config: `learners.{algo}.seeds` = {seeds!r} repeats a seed")
        steps = spec.get("timesteps")
        if not isinstance(steps, int) or steps < 1:
            raise ConfigError(f"invalid config: `learners.{algo}.timesteps` = {steps!r} is outside the allowed range >= 1")
        path = Path(spec.get("train_config") or "")
        path = path if path.is_absolute() else base / path
        if not path.is_file():
            raise ConfigError(f"invalid config: `learners.{algo}.train_config` = {spec.get('train_config')!r} is not a file")
        spec["train_config"] = str(path)
        if spec["tiers"] is not None:
            if not isinstance(spec["tiers"], list) or [t for t in spec["tiers"] if t not in tiers]:
                raise ConfigError(f"invalid config: `learners.{algo}.tiers` = {spec['tiers']!r} is outside the allowed values: a list of {tiers}")
    if not isinstance(cfg["baselines"], list) or [b for b in cfg["baselines"] if b not in _BASELINES]:
        raise ConfigError(f"invalid config: `baselines` = {cfg['baselines']!r} is outside the allowed values: a list of {list(_BASELINES)}")
    for key, lo in (("episodes", 1), ("num_envs", 1), ("cpus_per_job", 1)):
        v = cfg[key]
        if not isinstance(v, int) or isinstance(v, bool) or v < lo:
            raise ConfigError(f"invalid config: `{key}` = {v!r} is outside the allowed range >= {lo}")
    from accd_gym.envs.task import HELD_OUT_WAKE_SEEDS

    if cfg["episodes"] > len(HELD_OUT_WAKE_SEEDS):
        raise ConfigError(f"invalid config: `episodes` = {cfg['episodes']} is outside the allowed range [1, {len(HELD_OUT_WAKE_SEEDS)}] (the held-out wake seeds)")
    return cfg


def load_config(path: str | Path, *, quick: bool = False) -> dict[str, Any]:
    """A validated benchmark config from a JSON file (paths in it relative to the repository,
    the file's folder's parent)."""
    from accd_gym.envs.config import read_json_object

    p = Path(path).resolve()
    cfg = validate_config(read_json_object(p, "benchmark config"), quick=quick, root=p.parent.parent)
    cfg["source"] = str(p)
    return cfg


@dataclass(frozen=True)
class Job:
    """One training run of the benchmark: an algorithm's recipe on a tier with a seed."""

    tier: str
    algo: str
    seed: int
    train_config: str
    timesteps: int

    @property
    def name(self) -> str:
        """The run's folder name."""
        return f"{self.tier}_{self.algo}_seed{self.seed}"


def jobs(cfg: dict[str, Any]) -> list[Job]:
    """Every training job of a validated config, in (tier, algorithm, seed) order."""
    out = []
    for tier in cfg["tiers"]:
        for algo, spec in cfg["learners"].items():
            if spec["tiers"] is not None and tier not in spec["tiers"]:
                continue
            out += [Job(tier, algo, s, spec["train_config"], spec["timesteps"]) for s in spec["seeds"]]
    return out


def _episode_record(eps: Sequence[Any]) -> dict[str, Any]:
    """What the report needs of an evaluation: per episode, captured, miss distance, capture time."""
    return {
        "captured": [bool(e.captured) for e in eps],
        "min_distance": [float(e.min_distance) for e in eps],
        "capture_time": [None if e.capture_time is None else float(e.capture_time) for e in eps],
        "outcome": [e.outcome for e in eps],
    }


def evaluate_policy(policy: Any, tier: str, episodes: int, num_envs: int, num_threads: int = 0) -> dict[str, Any]:
    """``policy`` on the tier's first ``episodes`` held-out episodes: the per-episode record."""
    from accd_gym.evals.episodes import run_episodes
    from accd_gym.envs.task import HELD_OUT_WAKE_SEEDS

    eps = run_episodes(policy, episodes, wake_seeds=list(HELD_OUT_WAKE_SEEDS[:episodes]), num_envs=num_envs,
                       num_threads=num_threads, config={"tier": tier})
    return _episode_record(eps)


#: A finished job's result in its run folder: what a rerun of the benchmark into the same
#: ``--out`` reuses when the job's key (:func:`job_key`) is unchanged.
RESULT_FILE = "result.json"


@functools.lru_cache(maxsize=1)
def build_digest() -> str:
    """SHA-256 of the code a result comes from: the native extension's bytes and the package's
    Python sources (the version number alone does not change with a rebuild)."""
    import hashlib

    from accd_gym import _core

    h = hashlib.sha256(Path(_core.__file__).read_bytes())
    for src in sorted(Path(__file__).parent.rglob("*.py")):
        h.update(src.relative_to(Path(__file__).parent).as_posix().encode())
        h.update(src.read_bytes())
    return h.hexdigest()


def job_key(job: Job, episodes: int, num_envs: int) -> dict[str, Any]:
    """What a job's result depends on: the job, the training config's bytes (SHA-256), the tier's
    configuration, the code (:func:`build_digest`), the evaluation's episodes and batch size. A
    stored result with another key is not reused."""
    import hashlib

    from accd_gym.envs.tiers import tier as _tier

    return {"job": dict(job.__dict__), "train_config_sha256": hashlib.sha256(Path(job.train_config).read_bytes()).hexdigest(),
            "tier_config": _tier(job.tier).config(), "build": build_digest(), "episodes": episodes, "num_envs": num_envs}


def _stored_result(run: Path, key: dict[str, Any]) -> Optional[dict[str, Any]]:
    """The result stored in ``run`` when its key equals ``key`` (None otherwise or unreadable)."""
    try:
        stored = json.loads((run / RESULT_FILE).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(stored, dict) or stored.get("key") != json.loads(json.dumps(key)):
        return None
    return stored


def run_job(job: Job, out: str, episodes: int, num_envs: int, num_threads: int = 0) -> dict[str, Any]:
    """Trains ``job`` into ``out/runs/<name>`` and evaluates it: its metrics and episode record
    (also ``out/runs/<name>/result.json``).

    Resumable: a job whose run folder holds a result of the same :func:`job_key` is not run again
    (``"reused": true``); a run interrupted while training (Ctrl+C, a killed process) continues
    from its latest checkpoint (:func:`accd_gym.learning.training.resume`) to the same total; anything
    else starts the run afresh."""
    from accd_gym.learning import training
    from accd_gym.envs.config import read_json_object
    from accd_gym.evals.policies import load_policy

    run = Path(out) / "runs" / job.name
    key = job_key(job, episodes, num_envs)
    stored = _stored_result(run, key)
    if stored is not None:
        return stored["result"] | {"reused": True}
    raw = read_json_object(job.train_config, "train_config (training config)")
    raw["env"] = {"tier": job.tier}
    raw["seed"] = job.seed
    raw["total_timesteps"] = job.timesteps
    raw["num_threads"] = num_threads
    updates = raw.get("update_threads", 0)
    # (A value that is not an integer is left for validate_config to refuse, naming it.)
    if num_threads > 0 and type(updates) is int and updates > num_threads:
        # A job with a CPU budget (Ray's cpus_per_job) keeps its gradient updates within it.
        raw["update_threads"] = num_threads
    cfg = training.validate_config(raw)
    t0 = time.perf_counter()
    if _continues(run, cfg):
        meta = training.resume(run, progress=False)
    else:
        meta = training.train(cfg, run, progress=False)
    train_s = time.perf_counter() - t0
    t1 = time.perf_counter()
    record = evaluate_policy(load_policy(str(run)), job.tier, episodes, num_envs, num_threads)
    result = {"job": job.__dict__, "name": job.name, "status": meta["status"], "timesteps": meta["timesteps"],
              "train_wall_s": round(train_s, 2), "eval_wall_s": round(time.perf_counter() - t1, 2),
              "steps_per_s": meta.get("steps_per_s"), "run": str(run), "episodes": record}
    if meta["status"] == "done":
        from accd_gym import files

        files.write_text(run / RESULT_FILE, json.dumps({"key": key, "result": result}))
    return result | {"reused": False}


def _continues(run: Path, cfg: dict[str, Any]) -> bool:
    """``run`` holds an unfinished run of the training config ``cfg`` with a checkpoint, which
    :func:`accd_gym.learning.training.resume` continues (it refuses finished runs and runs without a
    checkpoint; the config check is the benchmark's: another recipe starts afresh)."""
    from accd_gym.learning import training

    try:
        meta = json.loads((run / "run.json").read_text())
    except (OSError, ValueError):
        return False
    return (isinstance(meta, dict) and meta.get("status") != "done" and training.latest_checkpoint(run) is not None
            and meta.get("config") == json.loads(json.dumps(cfg)))


def _run_jobs(todo: list[Job], cfg: dict[str, Any], out: Path, ray_address: Optional[str],
              progress: Callable[[str], None]) -> list[dict[str, Any]]:
    """Runs the jobs locally (in order) or as Ray tasks; returns their results in job order."""
    if ray_address is None:
        results = []
        for i, job in enumerate(todo):
            progress(f"[{i + 1}/{len(todo)}] training {job.name} ({job.timesteps} steps)")
            results.append(run_job(job, str(out), cfg["episodes"], cfg["num_envs"]))
        return results
    from accd_gym.evals import distributed

    ray = distributed.connect(ray_address)
    task = ray.remote(num_cpus=cfg["cpus_per_job"], max_retries=1)(run_job)
    # Longest first, so that the long jobs do not start last: an off-policy learner's job (SAC:
    # measured at 330 steps/s with one thread, a gradient step every 4 env steps) costs several
    # times a PPO job of more steps (3,800 steps/s).
    order = sorted(range(len(todo)), key=lambda i: (todo[i].algo == "ppo", -todo[i].timesteps, i))
    refs = [task.remote(todo[i], str(out), cfg["episodes"], cfg["num_envs"], cfg["cpus_per_job"]) for i in order]
    done: dict[int, dict[str, Any]] = {}
    pending = dict(zip(refs, order))
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1)
        i = pending.pop(ready[0])
        done[i] = ray.get(ready[0])
        progress(f"[{len(done)}/{len(todo)}] finished {todo[i].name}")
    return [done[i] for i in range(len(todo))]


def _baseline_policy(name: str, tier: str) -> Any:
    """The baseline ``name`` built for the tier's configuration (the LQR is designed on the
    tier's physics: its base configuration, the nominal draw of a randomized tier)."""
    from accd_gym.control.baselines import make_baseline

    return make_baseline(name, 0, {"tier": tier})


def iqm(values: Sequence[float]) -> float:
    """Interquartile mean (rliable's: ``scipy.stats.trim_mean(values, 0.25)``)."""
    from accd_gym.evals.sweep import iqm as _iqm

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


def _medians(record: dict[str, Any]) -> tuple[float, Optional[float]]:
    miss = float(np.median(record["min_distance"]))
    times = [t for t in record["capture_time"] if t is not None]
    return miss, (float(np.median(times)) if times else None)


def summarize(cfg: dict[str, Any], results: list[dict[str, Any]], baselines: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """The report's numbers per tier: learned algorithms (IQM, interval, per-seed rates),
    baselines (rate, Wilson interval), medians, and the McNemar comparison."""
    from accd_gym.evals.evaluation import mcnemar_exact, wilson_interval

    tiers: dict[str, Any] = {}
    for tier in cfg["tiers"]:
        rows: dict[str, Any] = {}
        runs = [r for r in results if r["job"]["tier"] == tier]
        for algo in cfg["learners"]:
            mine = sorted((r for r in runs if r["job"]["algo"] == algo), key=lambda r: r["job"]["seed"])
            if not mine:
                continue
            caps = [r["episodes"]["captured"] for r in mine]
            rates = [float(np.mean(c)) for c in caps]
            lo, hi = stratified_bootstrap(caps)
            pooled = {k: sum((r["episodes"][k] for r in mine), []) for k in ("min_distance", "capture_time")}
            miss, ttc = _medians(pooled)
            rows[algo] = {"kind": "learned", "seeds": [r["job"]["seed"] for r in mine], "rates": rates,
                          "iqm": iqm(rates), "ci95": [lo, hi], "miss_median_m": miss, "capture_time_median_s": ttc,
                          "train_wall_s": [r["train_wall_s"] for r in mine], "steps_per_s": [r["steps_per_s"] for r in mine]}
        for name, rec in baselines.get(tier, {}).items():
            if rec is None:
                continue
            k, n = int(sum(rec["captured"])), len(rec["captured"])
            miss, ttc = _medians(rec)
            rows[name] = {"kind": "classical" if name in ("guidance", "lqr") else "trivial", "rate": k / n,
                          "ci95": list(wilson_interval(k, n)), "miss_median_m": miss, "capture_time_median_s": ttc}
        comparison = None
        learned = [(float(np.mean(r["episodes"]["captured"])), r) for r in runs]
        classical = [(rows[b]["rate"], b) for b in ("guidance", "lqr") if b in rows]
        if learned and classical:
            best_rate, best = max(learned, key=lambda x: x[0])
            c_rate, c_name = max(classical, key=lambda x: x[0])
            a = np.asarray(best["episodes"]["captured"])
            b = np.asarray(baselines[tier][c_name]["captured"])
            only_a, only_b = int(np.sum(a & ~b)), int(np.sum(~a & b))
            comparison = {"learned": best["name"], "learned_rate": best_rate, "classical": c_name, "classical_rate": c_rate,
                          "both": int(np.sum(a & b)), "only_learned": only_a, "only_classical": only_b,
                          "neither": int(np.sum(~a & ~b)), "p_value": mcnemar_exact(only_a, only_b)}
        tiers[tier] = {"policies": rows, "mcnemar": comparison}
    return tiers


def performance_profile(results: list[dict[str, Any]], baselines: dict[str, dict[str, Any]],
                        taus: np.ndarray) -> dict[str, list[float]]:
    """Per policy, the fraction of its runs (every tier and seed) whose capture rate is at least
    each tau (rliable's performance profile on the run scores)."""
    scores: dict[str, list[float]] = {}
    for r in results:
        scores.setdefault(r["job"]["algo"].upper(), []).append(float(np.mean(r["episodes"]["captured"])))
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
    from accd_gym.files import save_figure

    save_figure(fig, path)
    plt.close(fig)


def _pct(x: float) -> str:
    return f"{100 * x:.1f} %"


def _reuse_note(doc: dict[str, Any]) -> str:
    """The header's account of jobs reused from an earlier invocation into the same folder."""
    reused = [r for r in doc["runs"] if r.get("reused")]
    if not reused:
        return ""
    minutes = sum(r["train_wall_s"] + r["eval_wall_s"] for r in reused) / 60
    return (f"; {len(reused)} of {len(doc['runs'])} jobs were finished by an earlier invocation into the same folder "
            f"and reused (their training and evaluation took {minutes:.1f} min then)")


def report_markdown(doc: dict[str, Any]) -> str:
    """The benchmark report (docs/benchmark.md)."""
    from accd_gym.envs.tiers import TIERS

    cfg = doc["config"]
    learners = ", ".join(f"{a.upper()} {len(s['seeds'])} seeds x {s['timesteps']:,} steps"
                         + (f" (tiers {', '.join(s['tiers'])})" if s["tiers"] else "") for a, s in cfg["learners"].items())
    learned = (f"Learned: {learners}, trained on training wake seeds only. Capture rate of a learned algorithm: the IQM "
               "over seeds with a 95 % two-level stratified bootstrap interval (seeds, then episodes); of a baseline: "
               if learners else f"No learned policies in this run (`{Path(cfg.get('source', '')).name or 'config'}`: baselines "
               "only). Capture rate of a baseline: ")
    lines = [
        "# accd-gym benchmark",
        "",
        f"Generated by `{doc['command']}` on {doc['date']} ({doc['machine']}); wall time {doc['wall_time_s'] / 60:.1f} min "
        f"(training {doc['train_wall_s'] / 60:.1f} min, baselines {doc['baseline_wall_s'] / 60:.1f} min)"
        + _reuse_note(doc) + ".",
        "",
        f"Every policy of a tier meets the same {cfg['episodes']} held-out episodes (episode k: seed 20240607 + k, "
        f"held-out wake seed k). {learned}the rate with its Wilson 95 % interval. Miss distance: the smallest "
        "capture-point-to-boom distance of the episode; time to capture over captured episodes only.",
    ]
    for tier, t in doc["tiers"].items():
        lines += ["", f"## {tier} (`{TIERS[tier].id}`)", "", TIERS[tier].summary + ".", "",
                  "| policy | capture rate | 95 % interval | per seed | miss median (m) | time to capture median (s) |",
                  "|---|---|---|---|---|---|"]
        for name, row in t["policies"].items():
            lo, hi = row["ci95"]
            ttc = "-" if row["capture_time_median_s"] is None else f"{row['capture_time_median_s']:.1f}"
            if row["kind"] == "learned":
                seeds = ", ".join(_pct(r) for r in row["rates"])
                lines.append(f"| {name.upper()} (IQM of {len(row['rates'])}) | {_pct(row['iqm'])} | {_pct(lo)} - {_pct(hi)} "
                             f"| {seeds} | {row['miss_median_m']:.2f} | {ttc} |")
            else:
                lines.append(f"| {name} | {_pct(row['rate'])} | {_pct(lo)} - {_pct(hi)} | - | {row['miss_median_m']:.2f} | {ttc} |")
        m = t["mcnemar"]
        if m:
            lines += ["", f"Best learned run `{m['learned']}` ({_pct(m['learned_rate'])}) vs best classical `{m['classical']}` "
                      f"({_pct(m['classical_rate'])}), paired on the same episodes: both {m['both']}, learned only "
                      f"{m['only_learned']}, classical only {m['only_classical']}, neither {m['neither']}; exact McNemar "
                      f"p = {m['p_value']:.3g} (both picked as the best on these episodes)."]
    lines += ["", "## Performance profile", "", "![performance profile](figures/benchmark_profile.png)", "",
              "Fraction of each policy's runs (every tier; learned: every seed) whose capture rate is at least tau."]
    return "\n".join(lines) + "\n"


def run(config: dict[str, Any], out: str | Path, *, ray_address: Optional[str] = None, docs: Optional[Path] = None,
        command: str = "accd-gym benchmark", progress: Callable[[str], None] = print) -> dict[str, Any]:
    """Runs the benchmark of a validated config into ``out``; returns the report document
    (also ``out/benchmark.json``, ``out/benchmark.md``, ``out/performance_profile.png``; with
    ``docs``, docs/benchmark.md and docs/figures/benchmark_profile.png there too)."""
    import datetime

    from accd_gym import files

    # before the jobs: a read-only folder (or --docs folder) is refused at once
    out = files.writable_folder(Path(out).resolve())
    if docs is not None:
        files.writable_folder(docs, "--docs")
        files.writable_folder(docs / "figures", "--docs")
    t0 = time.perf_counter()
    todo = jobs(config)
    results = _run_jobs(todo, config, out, ray_address, progress)
    train_s = time.perf_counter() - t0
    t1 = time.perf_counter()
    baselines: dict[str, dict[str, Any]] = {}
    for tier in config["tiers"]:
        baselines[tier] = {}
        for name in config["baselines"]:
            policy = _baseline_policy(name, tier)
            progress(f"baseline {name} on {tier}")
            baselines[tier][name] = evaluate_policy(policy, tier, config["episodes"], config["num_envs"])
    baseline_s = time.perf_counter() - t1
    taus = np.linspace(0.0, 1.0, 101)
    profile = performance_profile(results, baselines, taus)
    doc = {
        "command": command,
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "machine": f"{platform.machine()}, {_cpus()} CPUs, Python {platform.python_version()}",
        "config": config,
        "wall_time_s": time.perf_counter() - t0,
        "train_wall_s": train_s,
        "baseline_wall_s": baseline_s,
        "tiers": summarize(config, results, baselines),
        "runs": [{k: v for k, v in r.items() if k != "episodes"} | {"capture_rate": float(np.mean(r["episodes"]["captured"]))}
                 for r in results],
        "profile": {"tau": taus.tolist(), **profile},
    }
    files.write_text(out / "benchmark.json", json.dumps(doc, indent=1))
    files.write_text(out / "episodes.json", json.dumps({"runs": {r["name"]: r["episodes"] for r in results},
                                                        "baselines": baselines}))
    files.write_text(out / "benchmark.md", report_markdown(doc).replace("figures/benchmark_profile.png", "performance_profile.png"))
    plot_profile(profile, taus, out / "performance_profile.png")
    if docs is not None:
        files.write_text(docs / "benchmark.md", report_markdown(doc))
        plot_profile(profile, taus, docs / "figures" / "benchmark_profile.png")
    return doc


def _cpus() -> int:
    import os

    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


__all__ = ["DEFAULTS", "RESULT_FILE", "Job", "build_digest", "job_key", "jobs", "load_config", "validate_config", "run", "run_job", "evaluate_policy",
           "stratified_bootstrap", "summarize", "performance_profile", "report_markdown", "iqm"]

"""Distillation of a controller into a standalone network: behaviour cloning and DAgger.

``accd-gym distill --config training/distill_precision.json --out runs/NAME`` calls :func:`train`.
The *teacher* is any policy that labels observations with flap commands (a registered controller
such as the LQR, whose Kalman filter runs along the trajectory it labels, or a trained policy);
the *student* is a plain MLP on the observation the env gives with the ``history`` option (the
last ``k`` observations and commands: the tier's sensors are noisy and delayed, and the network
has no filter of its own). At run time the student is nothing but the network.

The loop (Ross, Gordon and Bagnell 2011):

* **round 0** (behaviour cloning's data): the teacher flies ``teacher_steps`` environment steps;
  every visited observation is stored with the teacher's command.
* **rounds 1..rounds** (DAgger): each step the command sent is the teacher's with probability
  ``beta_i = beta.start * beta.decay ** (i - 1)``, else the student's (per env and step); the
  teacher labels *every* visited observation (its filter is told the command actually sent,
  ``sent(offset)``, so its estimate follows the student's trajectory). ``round_steps`` steps per
  round, added to the aggregated dataset.
* after every round the student is trained on the whole aggregated dataset: ``updates`` Adam
  steps of ``batch_size`` samples drawn uniformly, mean squared error between the student's mean
  action and the teacher's command.

``rounds = 0`` is behaviour cloning. Observations are normalised with the mean and variance of
round 0's data (fixed afterwards; clipped at ``clip_obs``), saved as VecNormalize statistics.

A recipe is a JSON object (``training/distill_*.json``); every key but ``trainer`` is optional:

================== ================================================================================
key                meaning
================== ================================================================================
trainer            ``"distill"`` (what tells a recipe from an SB3 or RLlib training config)
teacher            the teacher policy's spec (default ``"lqr"``; the CLI resolves it like
                   ``accd-gym evaluate --policy``: a controller, a shipped policy, a run folder),
                   built for the env's configuration; a trained teacher (a residual policy) is
                   told the commands sent too. A teacher given as a path is recorded by its
                   digest (``run.json``'s ``teacher_digest``): a run resumes only with it unchanged
env                environment config overrides and env options, as in a training config; the
                   student observes what ``history`` gives (``true_observation`` is not taken)
seed               seed of the envs (training wake seeds only), the mixing and the network
num_envs           parallel episodes while collecting (default 32)
num_threads        threads stepping the envs (0: one per core; changes no result)
torch_threads      threads PyTorch uses (default 1; a fixed number: the weights' last bits can
                   depend on it)
teacher_steps      environment steps of round 0 (the teacher alone)
rounds             DAgger rounds after round 0 (0: behaviour cloning)
round_steps        environment steps per DAgger round
beta               ``{"start", "decay"}``: the teacher's share of the commands in round ``i``
action_noise       optional: standard deviation (flap units) of Gaussian noise added to every
                   command sent, in every round, the labels staying the teacher's clean commands
                   (DART, Laskey et al. 2017): the data then show the teacher recovering from
                   the perturbations that an exploring or imperfect student meets (default: none)
updates            Adam steps after each round
batch_size         samples per Adam step
learning_rate      Adam's step size
net_arch           hidden layer widths of the student (default ``[256, 256]``)
activation_fn      ``"tanh"`` (default), ``"relu"`` or ``"elu"``
log_std_init       the saved policy's log standard deviation (RL fine-tuning starts from it;
                   the deterministic policy never uses it)
clip_obs           the normalised observation's clip
total_timesteps    optional: the environment steps of all rounds together; when given, it must
                   equal ``teacher_steps + rounds * round_steps`` (the benchmark's ``timesteps``)
device             PyTorch device (default ``"cpu"``)
================== ================================================================================

Outputs in ``out``, in the layout of an SB3 run (:mod:`accd_gym.learning.training`), so that
:func:`accd_gym.evals.policies.load_policy`, ``accd-gym evaluate --policy OUT``, the benchmark and
``scripts/export_networks.py`` take it as any run: ``final_model.zip`` (a stable-baselines3 PPO
model whose actor is the student; its critic is untrained), ``vecnormalize.pkl``, ``run.json``
(``"algo": "ppo"``, ``"trainer": "distill"``, ``"method"``: ``"bc"`` or ``"dagger"``, the
recipe under ``config``, one record per round under ``rounds``, ``status``) and
``checkpoints/``: per round its data (``data_NN.npz``) and the student after it
(``student_NN.zip``, written last). ``accd-gym distill --resume OUT`` (:func:`resume`) continues
an interrupted run after its last complete round; every round's envs, mixing draws and sample
order come from ``(seed, round)``, so the resumed run ends with the same weights, bit for bit,
as an uninterrupted one (on one machine, with the same ``torch_threads``).

RL fine-tuning from the student: a training config with ``init_from`` naming the run folder
(:mod:`accd_gym.learning.training`).
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import time
from pathlib import Path
from typing import Any, Callable, Optional

import numpy as np

from accd_gym import files
from accd_gym.control.registry import Policy, make_controller
from accd_gym.envs.agent_io import physics_config, split_agent_options
from accd_gym.envs.task import OBS_DIM, SEED_END
from accd_gym.errors import ConfigError, StateError
from accd_gym.envs.config import read_json_object
from accd_gym.learning.training import save_model, save_statistics, check_training_env, load_statistics, start_digest

#: The files a distillation run folder gets beside ``checkpoints/`` (checked before it starts).
RUN_FILES = ("run.json", "final_model.zip", "vecnormalize.pkl")

#: Defaults of a distillation recipe.
DEFAULTS: dict[str, Any] = {
    "trainer": "distill",
    "teacher": "lqr",
    "env": {},
    "seed": 0,
    "num_envs": 32,
    "num_threads": 0,
    "torch_threads": 1,
    "teacher_steps": 48_000,
    "rounds": 6,
    "round_steps": 48_000,
    "beta": {"start": 0.5, "decay": 0.5},
    "updates": 1_000,
    "batch_size": 512,
    "learning_rate": 1e-3,
    "net_arch": [256, 256],
    "activation_fn": "tanh",
    "log_std_init": -2.0,
    "clip_obs": 10.0,
    "total_timesteps": None,
    "device": "cpu",
}
_ACTIVATIONS = ("tanh", "relu", "elu")

#: Recipe keys without a default: absent unless given, so that the validated recipe of a run
#: made before the key existed is unchanged (and its stored results stay valid).
OPTIONAL_KEYS = ("action_noise",)

#: A function building the teacher: ``(spec, seed, config) -> Policy`` (config: the env's
#: configuration overrides, without env options).
TeacherFactory = Callable[[str, int, dict], Policy]


def is_recipe(raw: Any) -> bool:
    """Whether a parsed JSON config is a distillation recipe (``"trainer": "distill"``)."""
    return isinstance(raw, dict) and raw.get("trainer") == "distill"


def load_recipe(path: str | Path, **overrides: Any) -> dict[str, Any]:
    """A validated recipe from a JSON file plus overrides (None values ignored)."""
    raw = read_json_object(path, "distillation recipe")
    raw.update({k: v for k, v in overrides.items() if v is not None})
    return validate_recipe(raw)


def _int(cfg: dict[str, Any], key: str, low: int, high: int) -> None:
    v = cfg[key]
    if not isinstance(v, int) or isinstance(v, bool) or not low <= v <= high:
        raise ConfigError(f"invalid config: `{key}` = {v!r} is outside the allowed range: an integer in [{low}, {high}]")


def _number(value: Any, name: str, low: float, high: float, *, open_low: bool = False) -> float:
    ok = (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
          and (low < value if open_low else low <= value) and value <= high)
    if not ok:
        bracket = "(" if open_low else "["
        raise ConfigError(f"invalid config: `{name}` = {value!r} is outside the allowed range {bracket}{low:g}, {high:g}]")
    return float(value)


def _device_name(name: str) -> bool:
    """Whether PyTorch names a device type ``name`` (``"auto"``: stable-baselines3's choice);
    True without PyTorch installed (the run then stops at its import, saying so)."""
    if name == "auto":
        return True
    try:
        import torch
    except ImportError:
        return True
    try:
        torch.device(name)
    except (RuntimeError, ValueError):
        return False
    return True


def validate_recipe(raw: Any) -> dict[str, Any]:
    """Fills in defaults and checks every field; ConfigError names the field, the value and the
    allowed range."""
    if not isinstance(raw, dict):
        raise ConfigError(f"invalid config: a distillation recipe must be a JSON object, got {type(raw).__name__}")
    unknown = set(raw) - set(DEFAULTS) - set(OPTIONAL_KEYS) - {"description"}
    if unknown:
        raise ConfigError(f"invalid config: distillation recipe key(s) {sorted(unknown)} outside the allowed set "
                          f"{sorted([*DEFAULTS, *OPTIONAL_KEYS])}")
    cfg = json.loads(json.dumps(DEFAULTS))
    cfg.update(json.loads(json.dumps(raw)))
    if cfg["trainer"] != "distill":
        raise ConfigError(f"invalid config: `trainer` = {cfg['trainer']!r} is outside the allowed range ['distill']")
    if not isinstance(cfg["teacher"], str) or not cfg["teacher"]:
        raise ConfigError(f"invalid config: `teacher` = {cfg['teacher']!r} is outside the allowed range: a policy name "
                          "or path (as for `accd-gym evaluate --policy`)")
    for key, low, high in (("seed", 0, SEED_END - 1), ("num_envs", 1, 4096), ("num_threads", 0, 1024),
                           ("torch_threads", 1, 1024), ("teacher_steps", 1, 10**10), ("rounds", 0, 1000),
                           ("round_steps", 1, 10**10), ("updates", 0, 10**9), ("batch_size", 1, 10**7)):
        _int(cfg, key, low, high)
    beta = cfg["beta"]
    if not isinstance(beta, dict) or set(beta) - {"start", "decay"}:
        raise ConfigError(f"invalid config: `beta` = {beta!r} is outside the allowed range: an object with keys "
                          "'start' and 'decay'")
    beta = {"start": 0.5, "decay": 0.5, **beta}
    cfg["beta"] = {"start": _number(beta["start"], "beta.start", 0.0, 1.0),
                   "decay": _number(beta["decay"], "beta.decay", 0.0, 1.0)}
    cfg["learning_rate"] = _number(cfg["learning_rate"], "learning_rate", 0.0, 1.0, open_low=True)
    cfg["clip_obs"] = _number(cfg["clip_obs"], "clip_obs", 0.0, 1e6, open_low=True)
    cfg["log_std_init"] = _number(cfg["log_std_init"], "log_std_init", -20.0, 2.0)
    if "action_noise" in cfg:
        cfg["action_noise"] = _number(cfg["action_noise"], "action_noise", 0.0, 2.0)
    arch = cfg["net_arch"]
    if not isinstance(arch, list) or not arch or not all(
            isinstance(w, int) and not isinstance(w, bool) and 1 <= w <= 65_536 for w in arch):
        raise ConfigError(f"invalid config: `net_arch` = {arch!r} is outside the allowed range: a non-empty list of "
                          "layer widths (integers in [1, 65536])")
    if cfg["activation_fn"] not in _ACTIVATIONS:
        raise ConfigError(f"invalid config: `activation_fn` = {cfg['activation_fn']!r} is outside the allowed range "
                          f"{list(_ACTIVATIONS)}")
    if not isinstance(cfg["env"], dict):
        raise ConfigError(f"invalid config: `env` = {cfg['env']!r} is outside the allowed range: a JSON object")
    options, _ = split_agent_options(cfg["env"])
    if options.residual is not None or options.true_observation:
        raise ConfigError("invalid config: `env` of a distillation recipe takes the option `history` only (the "
                          "student is a standalone network; `residual` and `true_observation` are outside the "
                          "allowed set)")
    check_training_env(cfg["env"])
    if not isinstance(cfg["device"], str) or not _device_name(cfg["device"]):
        raise ConfigError(f"invalid config: `device` = {cfg['device']!r} is outside the allowed range: a PyTorch "
                          "device name (cpu, cuda, cuda:N, mps, auto)")
    total = cfg["teacher_steps"] + cfg["rounds"] * cfg["round_steps"]
    if cfg["total_timesteps"] is not None and cfg["total_timesteps"] != total:
        raise ConfigError(f"invalid config: `total_timesteps` = {cfg['total_timesteps']!r} is outside the allowed range: "
                          f"teacher_steps + rounds * round_steps = {total} (or leave it out)")
    cfg["total_timesteps"] = total
    return cfg


def beta_of(cfg: dict[str, Any], round_index: int) -> float:
    """The teacher's share of the commands sent in round ``round_index`` (1 in round 0)."""
    if round_index == 0:
        return 1.0
    return float(cfg["beta"]["start"] * cfg["beta"]["decay"] ** (round_index - 1))


def round_seed(seed: int, round_index: int, stream: int, bound: int = SEED_END) -> int:
    """A seed in [0, bound) derived from ``(seed, round, stream)`` (stream 0: the envs, 1: the
    mixing draws, 2: the sample order and torch)."""
    state = np.random.SeedSequence([int(seed), int(round_index), int(stream)]).generate_state(2, dtype=np.uint64)
    return int(state[0]) % int(bound)


# -- the student ------------------------------------------------------------------------------


def _make_student(cfg: dict[str, Any], env: Any) -> Any:
    """A stable-baselines3 PPO model on ``env`` whose actor is the student (seeded by ``seed``)."""
    import torch
    from stable_baselines3 import PPO

    act = {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU, "elu": torch.nn.ELU}[cfg["activation_fn"]]
    return PPO("MlpPolicy", env, seed=cfg["seed"], device=cfg["device"], n_steps=8, batch_size=8 * env.num_envs,
               verbose=0, policy_kwargs={"net_arch": {"pi": list(cfg["net_arch"]), "vf": list(cfg["net_arch"])},
                                         "activation_fn": act, "log_std_init": cfg["log_std_init"]})


def _actor_parameters(policy: Any) -> list[Any]:
    """The parameters of the student's mean action: the actor's hidden layers and the action layer."""
    return list(policy.mlp_extractor.policy_net.parameters()) + list(policy.action_net.parameters())


def _mean_action(policy: Any, x: Any) -> Any:
    """The student's mean action (a torch tensor) for normalised observations ``x``."""
    return policy.get_distribution(x).mode()


def student_actions(policy: Any, normalized: np.ndarray) -> np.ndarray:
    """The student's deterministic commands (N, 4) float32 in [-1, 1] for normalised observations."""
    import torch

    with torch.no_grad():
        x = torch.as_tensor(np.asarray(normalized, dtype=np.float32), device=policy.device)
        u = _mean_action(policy, x).cpu().numpy()
    return np.clip(u, -1.0, 1.0).astype(np.float32)


def fit(policy: Any, obs: np.ndarray, labels: np.ndarray, *, updates: int, batch_size: int, learning_rate: float,
        seed: int) -> float:
    """Trains the student's mean action on ``(obs, labels)`` (normalised observations, teacher
    commands): ``updates`` Adam steps on batches drawn uniformly with the generator of ``seed``;
    returns the mean squared error of the last 10 % of the steps (nan with no update)."""
    import torch

    if updates == 0 or len(obs) == 0:
        return float("nan")
    torch.manual_seed(seed)
    rng = np.random.Generator(np.random.PCG64(seed))
    x_all = torch.as_tensor(np.asarray(obs, dtype=np.float32), device=policy.device)
    y_all = torch.as_tensor(np.asarray(labels, dtype=np.float32), device=policy.device)
    params = _actor_parameters(policy)
    opt = torch.optim.Adam(params, lr=learning_rate)
    policy.set_training_mode(True)
    tail, losses = max(1, updates // 10), []
    for step in range(updates):
        idx = torch.as_tensor(rng.integers(0, len(obs), size=batch_size), device=policy.device)
        loss = torch.mean((_mean_action(policy, x_all[idx]) - y_all[idx]) ** 2)
        value = float(loss.detach())
        if not math.isfinite(value):
            raise ConfigError(f"invalid config: the student's training diverged (loss {value} at Adam step {step}); "
                              f"`learning_rate` = {learning_rate!r} is outside the range that trains it: lower it")
        opt.zero_grad()
        loss.backward()
        opt.step()
        if step >= updates - tail:
            losses.append(value)
    policy.set_training_mode(False)
    return float(np.mean(losses))


# -- collection -------------------------------------------------------------------------------


def collect(env: Any, teacher: Policy, steps: int, beta: float, rng: np.random.Generator,
            student: Optional[Callable[[np.ndarray], np.ndarray]] = None, *, noise: float = 0.0,
            noise_rng: Optional[np.random.Generator] = None) -> dict[str, Any]:
    """Runs ``env`` (an SB3 VecEnv; its observations' first 25 entries the current observation)
    from a reset for ``ceil(steps / num_envs)`` vector steps: each step the teacher labels every
    env's observation (its state advances along the trajectory actually flown), and the command
    sent is the teacher's with probability ``beta`` (per env and step, drawn from ``rng``), else
    the student's (``student``: observations -> commands; needed when ``beta < 1``). The teacher
    is told the commands sent (``sent(offset)``, when it has it) and restarted with each episode.
    ``noise`` > 0 adds Gaussian noise of that standard deviation (from ``noise_rng``) to every
    command sent, clipped to the flap range; the labels stay the teacher's own commands.

    Returns ``obs`` (the visited observations), ``labels`` (the teacher's commands for them),
    ``episodes`` and ``captures`` (of the episodes that ended) and ``agreement`` (the mean squared
    difference between the student's and the teacher's commands where the student acted)."""
    n = env.num_envs
    vsteps = -(-int(steps) // n)
    obs = env.reset()
    teacher.reset(None)
    xs = np.empty((vsteps * n, obs.shape[1]), dtype=np.float32)
    ys = np.empty((vsteps * n, 4), dtype=np.float32)
    episodes = captures = 0
    diff_sum, diff_n = 0.0, 0
    can_sent = hasattr(teacher, "sent")
    for t in range(vsteps):
        u_teacher = np.asarray(teacher.predict(obs[:, :OBS_DIM]), dtype=np.float32)
        if u_teacher.shape != (n, 4) or not np.isfinite(u_teacher).all():
            raise StateError(f"teacher {getattr(teacher, 'name', type(teacher).__name__)!r} gave commands of shape "
                             f"{u_teacher.shape} with non-finite or missing values; a teacher must label every "
                             "observation with finite flap commands (N, 4)")
        xs[t * n:(t + 1) * n] = obs
        ys[t * n:(t + 1) * n] = u_teacher
        if beta >= 1.0:
            sent = u_teacher
        else:
            if student is None:
                raise ValueError("collect with beta < 1 needs a student")
            u_student = student(obs)
            pick = rng.random(n) < beta
            sent = np.where(pick[:, None], u_teacher, u_student).astype(np.float32)
            acted = ~pick
            if acted.any():
                diff_sum += float(np.sum((u_student[acted] - u_teacher[acted]) ** 2))
                diff_n += int(acted.sum()) * 4
        if noise > 0.0:
            if noise_rng is None:
                raise ValueError("collect with noise > 0 needs a noise_rng")
            sent = np.clip(sent + noise * noise_rng.standard_normal((n, 4)), -1.0, 1.0).astype(np.float32)
        if can_sent and sent is not u_teacher:  # the teacher's own command unperturbed: nothing to tell
            offset = sent.astype(np.float64) - u_teacher.astype(np.float64)
            if np.count_nonzero(offset):
                teacher.sent(offset)
        obs, _, dones, infos = env.step(sent)
        if dones.any():
            ended = np.flatnonzero(dones)
            episodes += len(ended)
            captures += sum(bool(infos[i].get("captured")) for i in ended)
            teacher.reset(dones)
    return {"obs": xs, "labels": ys, "episodes": episodes, "captures": captures,
            "agreement": diff_sum / diff_n if diff_n else None}


# -- the run ----------------------------------------------------------------------------------


def _env(cfg: dict[str, Any], seed: int) -> Any:
    """The collection env (AccdVecEnv, training wake seeds) with the recipe's env options."""
    # deferred: stable-baselines3, an optional dependency (accd_gym.envs.sb3 imports it)
    from accd_gym.envs.sb3 import AccdVecEnv

    return AccdVecEnv(num_envs=cfg["num_envs"], seed=seed, num_threads=cfg["num_threads"], **cfg["env"])


def _normalizer(env: Any, clip_obs: float) -> Any:
    """A VecNormalize of ``env`` for the observations only, not updated by stepping."""
    from stable_baselines3.common.vec_env import VecNormalize

    norm = VecNormalize(env, norm_obs=True, norm_reward=False, clip_obs=clip_obs, training=False)
    return norm


def _data_path(out: Path, k: int) -> Path:
    return out / "checkpoints" / f"data_{k:02d}.npz"


def _student_path(out: Path, k: int) -> Path:
    return out / "checkpoints" / f"student_{k:02d}.zip"


def completed_rounds(out: str | Path) -> int:
    """How many rounds of a run folder are complete (their student saved): 0 for none."""
    folder = Path(out) / "checkpoints"
    done = sorted(int(m.group(1)) for p in folder.glob("student_*.zip") if (m := re.fullmatch(r"student_(\d+)\.zip", p.name)))
    k = 0
    while k in done and _data_path(Path(out), k).is_file():
        k += 1
    return k


def _write_meta(out: Path, meta: dict[str, Any]) -> None:
    files.write_text(out / "run.json", json.dumps(meta, indent=1, default=str))


def _save_data(path: Path, obs: np.ndarray, labels: np.ndarray) -> None:
    import io

    buf = io.BytesIO()
    np.savez(buf, obs=obs, labels=labels)
    files.write_bytes(path, buf.getvalue())


def teacher_digest(spec: str) -> Optional[str]:
    """SHA-256 of a teacher given as a path: a run folder's policy (its model and statistics,
    :func:`accd_gym.learning.training.start_digest`) or a model file's bytes; None for a name (a
    registered controller, a shipped policy: the package's own). A run records it, so that a
    run taught by a teacher trained again since is told apart from one taught by the teacher
    there now."""
    path = Path(spec)
    if path.is_dir():
        return start_digest(path)
    if path.is_file():
        return hashlib.sha256(path.read_bytes()).hexdigest()
    return None


def default_teacher(spec: str, seed: int, config: dict) -> Policy:
    """A registered controller as the teacher (the CLI resolves any policy spec instead)."""
    return make_controller(spec, seed, config)


def train(recipe: dict[str, Any], out: str | Path, *, make_teacher: Optional[TeacherFactory] = None,
          report: Optional[Callable[[str], None]] = None) -> dict[str, Any]:
    """Distils per ``recipe`` (:func:`validate_recipe`) into the run folder ``out``; returns the
    run summary (also ``out/run.json``). ``make_teacher`` builds the teacher from its spec
    (default: a registered controller); ``report`` gets one progress line per round."""
    cfg = validate_recipe(dict(recipe))
    out = files.writable_folder(out, "--out", RUN_FILES)
    # A fresh run would overwrite the folder's run, and that run's round checkpoints would be
    # read as this one's (completed_rounds, resume): refused, nothing of it touched.
    held = [name for name in RUN_FILES if (out / name).exists()]
    held += ["checkpoints"] if [*(out / "checkpoints").glob("data_*.npz"), *(out / "checkpoints").glob("student_*.zip")] else []
    if held:
        raise ConfigError(f"invalid config: --out {str(out)!r} already holds a run ({', '.join(held)}); continue an "
                          f"interrupted one with `accd-gym distill --resume {out}`, or choose another --out")
    meta = {"algo": "ppo", "trainer": "distill", "method": "bc" if cfg["rounds"] == 0 else "dagger",
            "config": cfg, "status": "training", "total_timesteps": cfg["total_timesteps"], "rounds": []}
    digest = teacher_digest(cfg["teacher"])
    if digest is not None:  # (absent for a named teacher: the summaries of runs made before stay as they were)
        meta["teacher_digest"] = digest
    _write_meta(out, meta)
    return _run(cfg, out, meta, 0, make_teacher, report)


def resume(run: str | Path, *, make_teacher: Optional[TeacherFactory] = None,
           report: Optional[Callable[[str], None]] = None) -> dict[str, Any]:
    """Continues an interrupted distillation run after its last complete round, with its recipe;
    the result is that of an uninterrupted run, bit for bit. ConfigError when ``run`` is not a
    distillation run folder or is complete."""
    out = Path(run)
    meta_path = out / "run.json"
    if not meta_path.is_file():
        raise ConfigError(f"invalid config: --resume {str(run)!r} is not a run folder (no run.json)")
    meta = files.read_user_json(meta_path, "run summary")
    if not isinstance(meta, dict) or meta.get("trainer") != "distill" or not isinstance(meta.get("config"), dict):
        raise ConfigError(f"invalid config: {str(meta_path)!r} is not the run summary of a distillation run")
    if meta.get("status") == "done":
        raise ConfigError(f"invalid config: run {str(run)!r} is complete; nothing to resume")
    try:
        cfg = validate_recipe(meta["config"])
    except ConfigError as e:
        raise ConfigError(f"invalid config: {str(meta_path)!r} holds an invalid recipe: {e}") from None
    if meta.get("teacher_digest") != teacher_digest(cfg["teacher"]):
        raise ConfigError(f"invalid config: run {str(run)!r} was taught by another policy than the teacher "
                          f"{cfg['teacher']!r} there now (trained again or replaced since): its rounds would mix two "
                          "teachers; start the run afresh in another --out")
    files.writable_folder(out, "--resume", RUN_FILES)
    start = min(completed_rounds(out), cfg["rounds"] + 1)
    meta["rounds"] = [r for r in meta.get("rounds", []) if r.get("round", 0) < start]
    meta.setdefault("resumed", []).append({"from_round": start})
    meta["status"] = "training"
    _write_meta(out, meta)
    return _run(cfg, out, meta, start, make_teacher, report)


def _run(cfg: dict[str, Any], out: Path, meta: dict[str, Any], start: int, make_teacher: Optional[TeacherFactory],
         report: Optional[Callable[[str], None]]) -> dict[str, Any]:
    """Rounds ``start``..``rounds`` of a run (the earlier ones' data and student loaded)."""
    import torch
    from stable_baselines3 import PPO

    torch.set_num_threads(cfg["torch_threads"])
    make_teacher = make_teacher or default_teacher
    physics = physics_config(cfg["env"])
    t0 = time.time()
    env = _env(cfg, round_seed(cfg["seed"], 0, 0, SEED_END - cfg["num_envs"]))
    try:
        norm = _normalizer(env, cfg["clip_obs"])
        model = _make_student(cfg, norm)
        obs_parts: list[np.ndarray] = []
        label_parts: list[np.ndarray] = []
        for k in range(start):
            with np.load(_data_path(out, k)) as z:
                obs_parts.append(z["obs"])
                label_parts.append(z["labels"])
        if start > 0:
            stats = load_statistics((out / "vecnormalize.pkl").read_bytes(), str(out / "vecnormalize.pkl"),
                                    obs_dim=env.observation_space.shape[0])
            norm.obs_rms = stats.obs_rms
            saved = PPO.load(str(_student_path(out, start - 1)), device=cfg["device"])
            model.policy.load_state_dict(saved.policy.state_dict())
        try:
            for k in range(start, cfg["rounds"] + 1):
                r0 = time.time()
                beta = beta_of(cfg, k)
                teacher = make_teacher(cfg["teacher"], cfg["seed"], dict(physics))
                rng = np.random.Generator(np.random.PCG64(round_seed(cfg["seed"], k, 1)))
                env.seed(round_seed(cfg["seed"], k, 0, SEED_END - cfg["num_envs"]))
                steps = cfg["teacher_steps"] if k == 0 else cfg["round_steps"]
                noise = cfg.get("action_noise") or 0.0
                data = collect(env, teacher, steps, beta, rng,
                               student=lambda o: student_actions(model.policy, norm.normalize_obs(o)), noise=noise,
                               noise_rng=np.random.Generator(np.random.PCG64(round_seed(cfg["seed"], k, 3))))
                if k == 0:
                    x = data["obs"].astype(np.float64)
                    norm.obs_rms.mean = x.mean(axis=0)
                    norm.obs_rms.var = x.var(axis=0)
                    norm.obs_rms.count = float(len(x))
                    save_statistics(norm, out / "vecnormalize.pkl")
                _save_data(_data_path(out, k), data["obs"], data["labels"])
                obs_parts.append(data["obs"])
                label_parts.append(data["labels"])
                x_all = norm.normalize_obs(np.concatenate(obs_parts)).astype(np.float32)
                loss = fit(model.policy, x_all, np.concatenate(label_parts), updates=cfg["updates"],
                           batch_size=cfg["batch_size"], learning_rate=cfg["learning_rate"],
                           seed=round_seed(cfg["seed"], k, 2, 2**63))
                del x_all
                save_model(model, _student_path(out, k))
                record = {"round": k, "beta": beta, "steps": len(data["obs"]), "dataset": int(sum(map(len, obs_parts))),
                          "episodes": data["episodes"], "captures": data["captures"],
                          "student_mse": data["agreement"], "train_mse": loss, "wall_s": round(time.time() - r0, 1)}
                meta["rounds"].append(record)
                meta["timesteps"] = record["dataset"]
                _write_meta(out, meta)
                if report is not None:
                    rate = f"{data['captures']}/{data['episodes']}" if data["episodes"] else "no episode ended"
                    agree = "" if data["agreement"] is None else f", student-teacher MSE {data['agreement']:.4f}"
                    report(f"round {k}/{cfg['rounds']} (beta {beta:.3f}): {len(data['obs'])} steps, captured {rate}"
                           f"{agree}; dataset {record['dataset']}, train MSE {loss:.5f}; {record['wall_s']} s")
        except KeyboardInterrupt as e:
            meta.update(status="interrupted", interrupted_by=str(e) or "SIGINT",
                        wall_time_s=round(meta.get("wall_time_s", 0.0) + time.time() - t0, 1))
            _write_meta(out, meta)
            return meta
        save_model(model, out / "final_model.zip")
        meta.update(status="done", wall_time_s=round(meta.get("wall_time_s", 0.0) + time.time() - t0, 1),
                    torch_version=torch.__version__)
        meta.pop("interrupted_by", None)
        _write_meta(out, meta)
        return meta
    finally:
        env.close()


__all__ = ["DEFAULTS", "OPTIONAL_KEYS", "RUN_FILES", "TeacherFactory", "beta_of", "collect", "completed_rounds", "default_teacher",
           "fit", "is_recipe", "load_recipe", "resume", "round_seed", "student_actions", "train", "validate_recipe"]

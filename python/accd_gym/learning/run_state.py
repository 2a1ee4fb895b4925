"""What a run folder holds against the training config that should fill it: a finished
training of that config (reuse it), an unfinished one with a checkpoint (resume it), or
neither (train afresh). The benchmark and the sweeps decide with these, so that an
interrupted invocation, rerun, trains only what is missing."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Optional

from accd_gym import files
from accd_gym.learning import distill, training

__all__ = ["continues", "read_meta", "same_recipe", "same_sources", "same_start", "same_teacher", "set_aside", "trained"]


def same_recipe(stored: Any, cfg: dict[str, Any]) -> bool:
    """``stored`` (a run.json's config) trains what ``cfg`` trains: equal but for the two fields
    that change no result: ``num_threads``, the env-stepping thread count (the batch is bitwise
    identical for any thread count), and ``checkpoint_every``, how often the run is saved. A run
    begun as a Ray task (one thread per job) thus continues or is reused locally (one thread per
    core), and the other way round. ``init_from`` and a distillation's ``teacher`` count by the
    name of the run folder they name, not its path: a benchmark folder moved or cloned elsewhere
    keeps its fine-tuned and distilled runs (their digests, :func:`same_start` and
    :func:`same_teacher`, tell a policy trained again apart)."""
    if not isinstance(stored, dict):
        return False
    ignore = {"num_threads", "checkpoint_every"}

    def comparable(c: dict[str, Any]) -> dict[str, Any]:
        out = {k: v for k, v in c.items() if k not in ignore}
        for key in ("init_from", "teacher"):
            if isinstance(out.get(key), str):
                out[key] = Path(out[key]).name
        return out

    return comparable(stored) == comparable(json.loads(json.dumps(cfg)))


def read_meta(run: Path) -> Any:
    """The run summary ``run/run.json`` (whatever JSON it holds), or None where it is missing or
    unreadable."""
    try:
        return json.loads((run / "run.json").read_text())
    except (OSError, ValueError):
        return None


def same_start(meta: Any, src: Optional[str | Path]) -> bool:
    """A run (its ``run.json`` summary ``meta``) of a fine-tuning that starts from the folder
    ``src`` (``init_from``) began from the policy that is there now: the digest it recorded
    equals the folder's (a student trained again since, or a run of an earlier version that
    recorded none, does not); true where ``src`` is None (no fine-tuning)."""
    if src is None:
        return True
    recorded = meta.get("init_from_digest") if isinstance(meta, dict) else None
    return isinstance(recorded, str) and recorded == training.start_digest(src)


def same_teacher(meta: Any, teacher: Optional[str | Path]) -> bool:
    """A distillation run (its ``run.json`` summary ``meta``) was taught by the teacher ``teacher``
    names now: the digest it recorded equals the teacher's now (:func:`distill.teacher_digest`;
    neither has one for a named teacher); true where ``teacher`` is None (no distillation)."""
    if teacher is None:
        return True
    recorded = meta.get("teacher_digest") if isinstance(meta, dict) else None
    return recorded == distill.teacher_digest(str(teacher))


def same_sources(meta: Any, init_from: Optional[str | Path], teacher: Optional[str | Path]) -> bool:
    """The policies a run (its ``run.json`` summary ``meta``) learned from are those there now:
    the one a fine-tuning started from (:func:`same_start`) and a distillation's teacher
    (:func:`same_teacher`); None for either: the run has none."""
    return same_start(meta, init_from) and same_teacher(meta, teacher)


def trained(run: Path, cfg: dict[str, Any]) -> bool:
    """``run`` holds a finished training of the config ``cfg`` with its final model and statistics
    (a fine-tuning: started from the policy in its ``init_from`` folder now; a distillation:
    taught by its teacher as it is now)."""
    meta = read_meta(run)
    return (isinstance(meta, dict) and meta.get("status") == "done" and (run / "final_model.zip").is_file()
            and (run / "vecnormalize.pkl").is_file() and same_recipe(meta.get("config"), cfg)
            and same_sources(meta, cfg.get("init_from"), cfg.get("teacher")))


def continues(run: Path, cfg: dict[str, Any], *, distilled: bool = False) -> bool:
    """``run`` holds an unfinished run of the training config ``cfg`` with a checkpoint, which
    :func:`accd_gym.learning.training.resume` continues (it refuses finished runs and runs without a
    checkpoint; another recipe starts afresh). ``distilled``: a distillation run
    (:func:`accd_gym.learning.distill.resume`; a checkpoint is a complete round)."""
    meta = read_meta(run)
    if not isinstance(meta, dict):
        return False
    saved = distill.completed_rounds(run) > 0 if distilled else training.latest_checkpoint(run) is not None
    return (meta.get("status") != "done" and saved
            and (not distilled or meta.get("trainer") == "distill") and same_recipe(meta.get("config"), cfg)
            and same_sources(meta, cfg.get("init_from"), cfg.get("teacher")))


def set_aside(run: Path) -> Optional[Path]:
    """Moves a run folder that holds another training than the one about to start there (another
    recipe, a run without a checkpoint) to ``<run's grandparent>/superseded/<name>-<k>`` (the
    benchmark's ``OUT/superseded``, a sweep's ``OUT/superseded``: beside ``runs/`` and
    ``trials/``), so that training afresh loses nothing of it; returns the new place, or None
    when ``run`` holds nothing (missing or empty)."""
    if not run.is_dir() or not any(run.iterdir()):
        return None
    return files.shelve_folder(run, run.parent.parent / "superseded")

"""Runs the design studies by name (``accd-gym study NAME... --out DIR``): the paper's section 4
cases (:mod:`accd_gym.studies.study`) and the studies past the paper
(:mod:`accd_gym.studies.fidelity`), each into ``<figure>.png``, ``<study>.json`` and ``<study>.md``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Optional, Sequence

from accd_gym import files as _files
from accd_gym.studies import fidelity
from accd_gym.studies.study import (
    EXTRA_STUDIES,
    SAMPLE_INTERVAL_S,
    STUDIES,
    CommandPhase,
    MaxTensionCase,
    case_metrics,
    markdown_table,
    max_tension_markdown,
    max_tension_metrics,
    max_tension_readings,
    plot_cases,
    plot_max_tension,
    simulate_case,
    simulate_max_tension,
    study_cases,
)


def _bar(total: int, desc: str, progress: bool) -> Any:
    if not progress:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="sample", leave=False)


_TITLES = {
    "material": "Fig. 15: tether material (250 m, 24 mm, no flap deflection)",
    "length": "Fig. 16: tether length (24 mm UHMWPE, Fig. 12 commands, no wake)",
    "length-wake": "Fig. 17: tether length in the aircraft's wake (8 deg, turbulence; Fig. 12 commands)",
    "diameter": "Fig. 18: tether diameter (250 m UHMWPE, Fig. 12 commands)",
    "selected": "Fig. 19: the selected tether (Table 3), no flap deflection",
}


def _jsonable(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def run_study(
    study: str,
    out_dir: Path,
    progress: bool = True,
    commands: Optional[Sequence[CommandPhase]] = None,
    dpi: int = 90,
    max_tension: MaxTensionCase = MaxTensionCase(),
    scheme: str = "explicit",
) -> dict[str, Any]:
    """Runs one study and writes ``<figure>.png``, ``<study>.json`` and ``<study>.md`` into ``out_dir``.

    Args:
        study: one of :data:`STUDIES` or :data:`EXTRA_STUDIES`.
        out_dir: output folder (created).
        progress: show a tqdm progress bar on stderr.
        commands: flap commands for the commanded studies (default :func:`fig12_commands`).
        dpi: resolution of the PNGs.
        max_tension: inputs of the ``max-tension`` study.
        scheme: the tether's integration scheme of ``fig9`` and ``tension`` (one of
            :data:`accd_gym.studies.fidelity.SCHEMES`; the other studies take ``explicit`` only).

    Returns:
        The JSON document written: per figure, per case, the metrics and the paper's numbers.
    """
    check_scheme([study], scheme)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    if study in ("fig9", *EXTRA_STUDIES):
        doc, md = fidelity.run_study(study, out_dir, dpi=dpi, progress=progress, scheme=scheme)
    elif study == "max-tension":
        case = max_tension
        samples = round(case.duration_s / (max(1, round(SAMPLE_INTERVAL_S / case.time_step)) * case.time_step))
        bar = _bar(samples, study, progress)
        result = simulate_max_tension(case, bar=bar)
        if bar is not None:
            bar.close()
        metrics = max_tension_metrics(result)
        readings = max_tension_readings(case)
        plot_max_tension(result, metrics, out_dir / "max-tension.png", dpi=dpi)
        doc = {
            "study": study,
            "inputs": {k: getattr(case, k) for k in case.__dataclass_fields__},
            "metrics": {k: _jsonable(v) for k, v in metrics.items()},
            "paper": {"mean_tension_N": "about 125e3 (Fig. 14)", "peak_tension_N": "about 225e3 (Fig. 14)"},
            "readings": readings,
            "figures": ["max-tension.png"],
        }
        md = f"## max-tension (Fig. 14)\n\n![max-tension](max-tension.png)\n\n{max_tension_markdown(metrics, readings)}"
    else:
        groups = study_cases(study, commands)
        total = 0
        for cases in groups.values():
            total += sum(round(c.duration_s / SAMPLE_INTERVAL_S) for c in cases)
        bar = _bar(total, study, progress)
        doc = {"study": study, "figures": [], "cases": {}}
        md = f"## {study}\n"
        for figure, cases in groups.items():
            results = [simulate_case(c, bar=bar) for c in cases]
            plot_cases(results, out_dir / f"{figure}.png", _TITLES[figure], dpi=dpi)
            rows = [(r.case, case_metrics(r)) for r in results]
            doc["figures"].append(f"{figure}.png")
            for case, m in rows:
                doc["cases"][case.key] = {
                    "label": case.label,
                    "preset": case.preset,
                    "wake": case.wake,
                    "duration_s": case.duration_s,
                    "commands": [vars(p) for p in case.commands],
                    "metrics": m,
                    "paper": case.paper,
                }
            md += f"\n### {_TITLES[figure]}\n\n![{figure}]({figure}.png)\n\n{markdown_table(rows)}"
        if bar is not None:
            bar.close()
    _files.write_text(out_dir / f"{study}.json", json.dumps(doc, indent=2))
    _files.write_text(out_dir / f"{study}.md", md)
    return doc


#: The studies that take ``scheme = "implicit_axial"``.
SCHEME_STUDIES = ("fig9", "tension")


def check_scheme(names: Sequence[str], scheme: str) -> None:
    """Raises ValueError naming the scheme and the allowed values, or the studies of ``names``
    (``all`` standing for :data:`STUDIES`) that do not take it."""
    names = [*(STUDIES if "all" in names else ()), *(n for n in names if n != "all")]
    fidelity.check_scheme(scheme)
    others = [n for n in names if n not in SCHEME_STUDIES]
    if scheme != "explicit" and others:
        raise ValueError(
            f"invalid config: scheme = {scheme!r} applies to the {' and '.join(SCHEME_STUDIES)} studies only, "
            f"not {', '.join(others)}; run those without it"
        )


def output_files(studies: Sequence[str]) -> list[str]:
    """The JSON and markdown files :func:`run` writes for ``studies`` (``all`` standing for
    :data:`STUDIES`); each study's figures come beside them."""
    names = list(dict.fromkeys([*(STUDIES if "all" in studies else ()), *(s for s in studies if s != "all")]))
    return [f for n in names for f in (f"{n}.json", f"{n}.md")] + (["summary.md"] if len(names) > 1 else [])


def run(
    studies: Sequence[str],
    out_dir: Path,
    progress: bool = True,
    dpi: int = 90,
    scheme: str = "explicit",
) -> dict[str, dict[str, Any]]:
    """Runs ``studies`` (names from :data:`STUDIES` or :data:`EXTRA_STUDIES`, or ``all`` for every
    one of :data:`STUDIES`) into ``out_dir``; with more than one, also writes ``summary.md`` (every
    study's tables). ``scheme``: the tether's integration scheme, ``explicit`` or, for the studies
    of :data:`SCHEME_STUDIES` only, ``implicit_axial``. Returns {study: its JSON document}."""
    names = list(dict.fromkeys([*(STUDIES if "all" in studies else ()), *(s for s in studies if s != "all")]))
    for name in names:
        if name not in STUDIES + EXTRA_STUDIES:
            raise ValueError(f"unknown study {name!r}; choose from {', '.join(STUDIES + EXTRA_STUDIES)} or all")
    check_scheme(names, scheme)
    docs = {}
    for name in names:
        docs[name] = run_study(name, out_dir, progress=progress, dpi=dpi, scheme=scheme)
    if len(names) > 1:
        parts = [(Path(out_dir) / f"{n}.md").read_text() for n in names]
        _files.write_text(Path(out_dir) / "summary.md", "# Design studies (paper section 4)\n\n" + "\n".join(parts))
    return docs

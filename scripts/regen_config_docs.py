"""Rewrites the generated sections of docs/environment.md, each marked
``<!-- generated: NAME() -->`` ... ``<!-- end generated -->``, from the declarations they come from:
``accd_gym.config.config_table_markdown()`` (the Rust field declarations) and
``accd_gym.tiers.tiers_markdown()`` (the benchmark tiers) and ``accd_gym.agent_io.agent_io_markdown()``
(the residual-control and history options). Run it after changing either;
tests/test_env.py and tests/test_tiers.py check the file against them."""

import re
import sys
from pathlib import Path

from accd_gym.agent_io import agent_io_markdown
from accd_gym.config import config_table_markdown
from accd_gym.tiers import tiers_markdown

GENERATORS = {
    "accd_gym.config.config_table_markdown()": config_table_markdown,
    "accd_gym.tiers.tiers_markdown()": tiers_markdown,
    "accd_gym.agent_io.agent_io_markdown()": agent_io_markdown,
}

path = Path(__file__).resolve().parents[1] / "docs" / "environment.md"
text = path.read_text()
pattern = re.compile(r"(<!-- generated: ([^>]*?) -->\n)(.*?)(\n<!-- end generated -->)", re.S)
found = {m.group(2) for m in pattern.finditer(text)}
missing = sorted(set(GENERATORS) - found)
if missing:
    sys.exit(f"{path}: no generated section for {missing}")


def regenerate(m: re.Match) -> str:
    name = m.group(2)
    if name not in GENERATORS:
        sys.exit(f"{path}: unknown generated section {name!r}")
    return m.group(1) + GENERATORS[name]() + m.group(4)


new = pattern.sub(regenerate, text)
if new != text:
    path.write_text(new)
    print(f"updated {path}")
else:
    print(f"{path} is up to date")

"""Rewrites the generated configuration table in docs/environment.md from the Rust declarations
(``accd_gym.config.config_table_markdown()``); run after changing a ``config_struct!`` field.
tests/test_env.py checks the file and the env docstrings against the declarations."""

import re
import sys
from pathlib import Path

from accd_gym.config import config_table_markdown

path = Path(__file__).resolve().parents[1] / "docs" / "environment.md"
text = path.read_text()
pattern = re.compile(r"(<!-- generated: [^>]*-->\n)(.*?)(\n<!-- end generated -->)", re.S)
if not pattern.search(text):
    sys.exit(f"{path}: no generated section")
new = pattern.sub(lambda m: m.group(1) + config_table_markdown() + m.group(3), text, count=1)
if new != text:
    path.write_text(new)
    print(f"updated {path}")
else:
    print(f"{path} is up to date")

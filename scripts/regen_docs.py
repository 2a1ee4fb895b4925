"""Rewrites the generated sections of README.md, docs/environment.md and docs/datasets.md from the declarations in
code. A section is marked ``<!-- generated: accd_gym.module.function() -->`` ...
``<!-- end generated -->``; the name is the function that makes it. Run it after changing a
declaration (a configuration field, the observation table, the reward terms, the episode end, a
tier); ``--check`` only reports stale sections and exits 1 (tests/test_docs_generated.py)."""

import sys
from pathlib import Path

from accd_gym.envs.tables import regenerate

ROOT = Path(__file__).resolve().parents[1]
check = "--check" in sys.argv[1:]
stale = []
for path in (ROOT / "README.md", ROOT / "docs" / "environment.md", ROOT / "docs" / "datasets.md"):
    text = path.read_text()
    new = regenerate(text, str(path))
    if new != text:
        stale.append(path)
        if not check:
            path.write_text(new)
for path in stale:
    print(f"{'stale' if check else 'updated'}: {path}")
if not stale:
    print("the generated sections are up to date")
sys.exit(1 if check and stale else 0)

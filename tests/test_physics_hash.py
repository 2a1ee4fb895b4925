"""The physics fingerprint: every output of a fixed set of episodes is unchanged.

``scripts/physics_hash.py`` hashes 8 envs x 700 agent steps under the default and the precision
configurations with the guidance controller and with seeded random flaps. The recorded hashes in
``tests/data/physics_hashes.json`` were taken on main at a3be75f, before the capture-layer rebuild;
a change of the numerical scheme must be measured, documented and recorded here on purpose.
"""

import importlib.util
import json
import pathlib

ROOT = pathlib.Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("physics_hash", ROOT / "scripts" / "physics_hash.py")
physics_hash = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(physics_hash)


def test_every_output_of_the_fixed_episodes_is_unchanged():
    recorded = json.loads((ROOT / "tests" / "data" / "physics_hashes.json").read_text())
    assert physics_hash.hashes() == recorded

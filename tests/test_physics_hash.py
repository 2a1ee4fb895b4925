"""The physics fingerprint: every output of a fixed set of episodes is unchanged.

``scripts/physics_hash.py`` hashes 8 envs x 700 agent steps under the default and the precision
configurations with the guidance controller and with seeded random flaps. The recorded hashes in
``tests/data/physics_hashes.json`` are those of the exact air scheme (``exact/*`` and
``exact_precision/*``) and of the default fast scheme (``default/*`` and ``precision/*``; the two
schemes compared in docs/decisions.md). A change of the numerical scheme must be measured,
documented and recorded here on purpose.
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


def test_the_exact_scheme_keeps_the_first_recorded_hashes():
    """The hashes of the exact air scheme are those recorded at a3be75f, when it was the default."""
    recorded = json.loads((ROOT / "tests" / "data" / "physics_hashes.json").read_text())
    assert recorded["exact/guidance"] == "d6fed458abe45c9cf44cdde420c94842f12849d1e456a563e8d36bf45ca40538"
    assert recorded["exact_precision/guidance"] == "03d06c1433336a36176a6943f9be9fd7096d17c21e34f550b620e4c3cb88d279"
    assert recorded["exact/random"] == "6d0eb50c47b2457a3076b3976be69829822afb99e5e2e74484d07f47b5891823"
    assert recorded["exact_precision/random"] == "c6a80359ea7e358f0a3c1a752e824e3b0ac10b52630808f30292d379fdc3d929"

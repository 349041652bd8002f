"""The package's surface: ``import bve_mj`` is cheap and every exported name resolves."""

import subprocess
import sys

import bve_mj


def test_importing_the_package_loads_nothing_heavy():
    code = (
        "import sys, bve_mj; from bve_mj.config import Settings; Settings(); "
        "heavy = [m for m in ('scipy.optimize', 'pinocchio', 'mujoco', 'cv2') if m in sys.modules]; "
        "print(','.join(heavy))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_every_exported_name_resolves():
    for name in bve_mj.__all__:
        assert getattr(bve_mj, name) is not None, name
    assert set(bve_mj.__all__) <= set(dir(bve_mj))
    try:
        bve_mj.not_a_name  # noqa: B018
    except AttributeError as exc:
        assert "not_a_name" in str(exc)
    else:
        raise AssertionError("an unknown name resolved")

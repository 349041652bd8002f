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


def test_one_blas_thread_reaches_blas_loaded_after_a_light_import():
    """``import bve_mj`` loads no BLAS; the CLI's and the workers' one-thread limit must still
    reach SciPy's (a multi-threaded BLAS changed an episode's path: plum, seed 2710367621,
    4.33 mm by the CLI before the lazy import, 4.25 after)."""
    code = (
        "import bve_mj; from bve_mj.threads import one_blas_thread\n"
        "from threadpoolctl import threadpool_info\n"
        "with one_blas_thread():\n"
        "    import scipy.optimize\n"
        "    libs = [i for i in threadpool_info() if i['user_api'] == 'blas']\n"
        "    print(len(libs), max(i['num_threads'] for i in libs))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    n_libs, threads = map(int, out.stdout.split())
    assert n_libs >= 1 and threads == 1

"""The one build step pyproject.toml cannot declare: ship the top-level ``models/`` (the robot
models people open, and the package reads) inside the package, as ``bve_mj/models``, where
``importlib.resources`` finds them in an installed wheel. An editable install reads
``models/`` from the checkout instead (:func:`bve_mj.robot.description.models_dir`)."""

from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py


class BuildPyWithModels(build_py):
    """``build_py``, then ``models/`` copied to ``<build>/bve_mj/models``."""

    def run(self) -> None:
        super().run()
        if getattr(self, "editable_mode", False):  # the checkout's models/ is read in place
            return
        source = Path("models")
        target = Path(self.build_lib) / "bve_mj" / "models"
        for path in sorted(source.rglob("*")):
            rel = path.relative_to(source)
            if path.is_file() and not any(part.startswith((".", "__")) for part in rel.parts):
                (target / rel).parent.mkdir(parents=True, exist_ok=True)
                self.copy_file(str(path), str(target / rel))


setup(cmdclass={"build_py": BuildPyWithModels})

"""Build hook only (metadata lives in pyproject.toml): the experiment files live in the top-level
``experiments/`` folder; a wheel ships them as package data of ``slamcli.experiments``, copied here."""

from pathlib import Path
from shutil import copyfile

from setuptools import setup
from setuptools.command.build_py import build_py


class BuildPyWithExperiments(build_py):
    """``build_py`` + copy ``experiments/*.toml`` into ``slamcli/experiments/`` of the build tree."""

    def run(self):
        super().run()
        target = Path(self.build_lib) / "slamcli" / "experiments"
        target.mkdir(parents=True, exist_ok=True)
        for f in sorted(Path(__file__).resolve().parent.joinpath("experiments").glob("*.toml")):
            copyfile(f, target / f.name)


setup(cmdclass={"build_py": BuildPyWithExperiments})

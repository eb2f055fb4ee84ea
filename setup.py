"""Package map: the client's top-level folders become subpackages of the one import name `benchtwin`.

Kept in setup.py (not pyproject.toml) only because the subpackage list is computed: every folder
with an ``__init__.py`` under ``app/``, ``twin/``, ``analysis/``, ``hw/``, ``models/`` and ``scenarios/`` is
installed as ``benchtwin.<folder>.<sub>``, so nothing called ``analysis`` or ``hw`` lands at the top
of site-packages.
"""

from setuptools import find_packages, setup

FOLDERS = ("app", "twin", "analysis", "hw", "models", "scenarios")

package_dir = {"benchtwin": "benchtwin"}
packages = ["benchtwin"] + [f"benchtwin.{p}" for p in find_packages("benchtwin")]
for folder in FOLDERS:
    package_dir[f"benchtwin.{folder}"] = folder
    packages.append(f"benchtwin.{folder}")
    packages += [f"benchtwin.{folder}.{sub}" for sub in find_packages(folder)]

setup(packages=packages, package_dir=package_dir)

"""The package layout that ``pyproject.toml`` cannot express: everything else is declared there.

``frontend/`` stays at the repository's top, where the dashboard is edited and served from in
a checkout, and is shipped inside the wheel as the package data ``backend/frontend/``
(``backend/api/routes/dashboard.py`` reads it from there when installed). Setuptools maps a
folder outside the packages only through ``package_dir`` with an explicit package list, which
pyproject's ``packages.find`` does not allow beside it.
"""

from setuptools import find_namespace_packages, setup

FRONTEND = ["backend.frontend",
            *(f"backend.frontend.{name}" for name in find_namespace_packages(where="frontend"))]

setup(
    packages=[*find_namespace_packages(include=["backend*", "sim*", "vision*"],
                                       exclude=["*.__pycache__"]), *FRONTEND],
    package_dir={"backend.frontend": "frontend"},
)

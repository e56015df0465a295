"""The shipped protocols (the paper's four experiments) and display profiles (``displays/``).

Data only: this folder is installed as the package ``fovexp.protocols`` (pyproject.toml maps
it), so that ``fovexp run validation`` and ``load_display("lg-oled55cx")`` find them from any
folder once fovexp is installed with pip. See :mod:`fovexp.resources`.
"""

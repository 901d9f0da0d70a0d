"""FMU runtime: standard-library Python only, bundled into every FMU.

``spec.py`` (what an FMU declares), ``framework.py`` (the one FMI glue, pythonfmu), one runtime
module per model (``sideslip_bank_observer.py``, ``car_plant.py``: maths, no FMI) and one tiny model file
per FMU in ``models/``. Relative imports only: the package is copied into each FMU under a
content-hashed name. Never imports numpy, cvxpy or the design code.
"""

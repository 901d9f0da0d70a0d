"""Shared fixtures: designs are solved once per session, FMUs built once per session."""
from __future__ import annotations

import pytest

from latobs.synthesis import designs


@pytest.fixture(scope="session")
def design_speed() -> dict:
    return designs.run("SideslipBankObserver")


@pytest.fixture(scope="session")
def design_tire() -> dict:
    return designs.run("SideslipBankObserverTire")


@pytest.fixture(scope="session")
def fmu_dir(tmp_path_factory, design_speed, design_tire):
    """The paper-000 observer FMUs (the two defaults and the two paper-faithful designs, the
    default observers of `latobs validate`) and the CarPlant FMU, built by the packaging step."""
    from latobs import packaging
    from latobs.synthesis import design_file

    out = tmp_path_factory.mktemp("fmus")
    for data in (design_speed, design_tire, designs.run("SideslipBankObserverPaper"),
                 designs.run("SideslipBankObserverTirePaper")):
        packaging.package_design(design_file.write(data, out), out)
    packaging.package_plant("CarPlant", None, out)
    return out

"""What the MBDS benchmarks share: the record, its tuning / held-out split and the output folder."""
from __future__ import annotations

import tempfile
from pathlib import Path

from latobs.synthesis.params import load_vehicle
from latobs.validation import replay as rp

SPLIT = 425.0          # s, the record's tuning / held-out split


def setup(out: Path | None, prefix: str):
    """(folder, record columns, the dataset's vehicle mbds_250lm): ``out`` made, or a new temporary one."""
    out = out or Path(tempfile.mkdtemp(prefix=prefix))
    out.mkdir(parents=True, exist_ok=True)
    return out, rp.load_csv(rp.resolve_csv("mbds")), load_vehicle("mbds_250lm")

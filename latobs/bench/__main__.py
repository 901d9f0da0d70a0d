"""``python -m latobs.bench``: the same as ``latobs bench``."""
from . import main

raise SystemExit(main())

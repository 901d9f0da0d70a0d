"""Data shipped with latobs: the real-vehicle record ``mbds-250lm/`` and its reader (:mod:`.records`)."""

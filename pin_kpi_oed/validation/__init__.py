"""Input validation shared by every command: option ranges, unit plausibility, output paths, file schemas.

``options.check_args`` runs before any work (``cli/app.py``); ``paths.check_outputs`` refuses output
paths that are folders, unwritable, an input of the same command or another output; ``units`` holds the
unit-plausibility guards every command uses; ``schema`` validates cell and design files (nested
unknown keys refused, text where a number belongs named by its field).
"""

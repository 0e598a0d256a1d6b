"""Imports every command module so that each registers itself on ``app``.

Add one line per command module. Command modules import only typer and the standard
library at module level.
"""

# isort: off

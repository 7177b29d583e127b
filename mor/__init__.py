"""MOR: Mobile Object Rearrangement with learned localization uncertainty."""

import mor.sim  # noqa: F401  (registers the Gymnasium environments)

__version__ = "0.1.0"

"""robopercept: a robotic-perception toolkit, every method implemented from its mathematics.

Importing the package is cheap: topics are imported on demand
(``from robopercept.imaging import canny``); nothing compiles and no torch is loaded.
"""

from __future__ import annotations

__version__ = "0.1.0"
__all__ = ["__version__"]

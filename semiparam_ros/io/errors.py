"""Exception types of :mod:`semiparam_ros.io`: the package's :class:`~semiparam_ros.errors.BagError`.

Kept so that ``from semiparam_ros.io.errors import BagError`` keeps working; the class is defined once,
in :mod:`semiparam_ros.errors`, under the package's root exception.
"""

from __future__ import annotations

from semiparam_ros.errors import BagError

__all__ = ["BagError"]

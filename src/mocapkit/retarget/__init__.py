"""Whole-body humanoid retargeting from either capture: human segment poses -> per-bone
scaled targets -> one QP per frame on the robot (Pinocchio + proxsuite). A robot is a
YAML file (``mocapkit/data/humanoids``).

The package is also the top-level function ``mocapkit.retarget(source, robot=...)``
(:func:`mocapkit.api.retarget`): importing a submodule makes ``mocapkit.retarget`` this
package, so the package itself forwards a call to that function.
"""

import sys
import types
from typing import Any


class _CallableModule(types.ModuleType):
    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        from mocapkit.api import retarget

        return retarget(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule

"""The former name of the tempokey package, kept so that scripts written for it still run.

``import tempokey_client as tk`` gives the same names as ``import tempokey as tk``; new code
imports ``tempokey``. The BVH reader that was ``bvh`` is ``tempokey.bvh`` (and read_bvh_clip()
in tempokey.formats reads a file straight into a clip).
"""

import warnings

from tempokey import *  # noqa: F401,F403 - the whole public API, re-exported
from tempokey import __all__  # noqa: F401

warnings.warn("tempokey_client is now the tempokey package: import tempokey",
              DeprecationWarning, stacklevel=2)

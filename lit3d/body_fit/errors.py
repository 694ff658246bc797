"""The body fit's error classes."""
from __future__ import annotations

from lit3d.utils.errors import Lit3dError


class BodyFitError(Lit3dError, ValueError):
    """A depth image the body fit cannot use (too few foreground points, a camera that does not
    see them): the message is one line naming the image and the problem."""


class BodyCheckpointError(Lit3dError, ValueError):
    """A body regressor checkpoint (``--body-init``) that cannot be used (missing, not a torch.save
    archive, another kind of checkpoint, weights that do not fit): one line naming the file."""

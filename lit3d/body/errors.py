"""The body fit's one error class."""
from __future__ import annotations

from lit3d.utils.errors import Lit3dError


class BodyFitError(Lit3dError, ValueError):
    """A depth image the body fit cannot use (too few foreground points, a camera that does not
    see them): the message is one line naming the image and the problem."""

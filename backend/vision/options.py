"""Options of the vision service that HTTP and the CLI share, in a module light enough for
the CLI's parser (no numpy): one place for their choices and defaults, so
``POST /api/v1/vision/calibrations`` and ``heliotwin vision calibrate`` fit the same
model to the same frames."""

from __future__ import annotations

from backend.errors import InputError

#: ``n_radial`` of a calibration: ``auto`` lets the frames decide the radial terms
#: (leave-one-out, ``vision.calibrate.choose_radial``), a number fixes them
N_RADIAL_CHOICES = ("auto", "0", "1", "2")
N_RADIAL_DEFAULT = "auto"


def parse_n_radial(text: str, field: str = "n_radial") -> int | None:
    """``n_radial`` as ``backend.vision.service.calibrate`` takes it: None for ``auto``,
    else the number; a 422 naming ``field`` for anything else."""
    if text not in N_RADIAL_CHOICES:
        raise InputError(422, f"{field}: must be auto, 0, 1 or 2, got {text!r}")
    return None if text == "auto" else int(text)

#: ``projection`` of a calibration: ``auto`` lets the frames choose the lens's projection
#: (leave-one-out, ``vision.calibrate.choose_projection``; equidistant unless another is
#: better by more than one standard error), a name fixes it — ``vision.cameras.PROJECTIONS``
#: after ``auto`` (spelt out here: this module stays free of numpy)
PROJECTION_CHOICES = ("auto", "equidistant", "equisolid", "stereographic", "orthographic")
PROJECTION_DEFAULT = "auto"


def parse_projection(text: str, field: str = "projection") -> str:
    """A calibration's ``projection`` as ``backend.vision.service.calibrate`` takes it; a 422
    naming ``field`` for anything else."""
    if text not in PROJECTION_CHOICES:
        raise InputError(422, f"{field}: must be one of {', '.join(PROJECTION_CHOICES)}, got "
                              f"{text!r}")
    return text

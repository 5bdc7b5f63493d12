"""``/api/v1/vision``: the sun in uploaded frames, fisheye calibrations, seed 003's tables."""

from __future__ import annotations

from pydantic import BaseModel, Field


class EphemerisRead(BaseModel):
    """The ephemeris sun (SPA, apparent elevation) and, for a fisheye, its pixel."""

    azimuth_deg: float
    elevation_deg: float
    centroid_px: list[float] | None = Field(
        None, description="fisheye only: [x, y] through the camera model; null below the "
                          "horizon")


class SunErrorRead(BaseModel):
    """Detected minus ephemeris."""

    separation_deg: float = Field(description="angle between the two on the sphere [°]")
    azimuth_deg: float | None = None
    elevation_deg: float | None = None
    distance_px: float | None = Field(None, description="fisheye: between the two pixels")


class DerivedCameraRead(BaseModel):
    """A fisheye scale derived from the image circle (no ``px_per_deg`` given)."""

    cx_px: float
    cy_px: float
    px_per_deg: float
    image_circle_radius_px: float
    projection: str
    how: str
    warning: str | None = None


class SunDetectionRead(BaseModel):
    """One frame's sun (``vision.analyse.analyse_frame``) as stored.

    A fisheye answers ``azimuth_deg``/``elevation_deg``; a pinhole
    ``pointing_error_deg`` [right, up] and ``pointing_error_mrad``; with time and place
    ``ephemeris`` and, when both suns are known, ``error``.
    """

    detection_id: int
    sun_found: bool
    confidence: float = Field(description="a calibrated probability [0, 1]")
    reason: str | None = Field(description="why no sun was found; null otherwise")
    centroid_px: list[float] | None = Field(description="[x, y]")
    method: str
    image_size_px: list[int] = Field(description="[width, height]")
    distance_from_ephemeris_px: float | None
    camera: str = Field(description="`fisheye` or `pinhole`")
    azimuth_deg: float | None = None
    elevation_deg: float | None = None
    pointing_error_deg: list[float | None] | None = None
    pointing_error_mrad: float | None = None
    ephemeris: EphemerisRead | None = None
    error: SunErrorRead | None = None
    camera_derived: DerivedCameraRead | None = None
    warnings: list[str]
    calibration_id: int | None
    timestamp: str | None = Field(description="UTC, ISO 8601")
    timestamp_source: str | None = Field(None, description=(
        "where the time comes from: `given` (the `timestamp` field), `file name (…)` (the "
        "time the file's name carries, backend/vision/frames.py), null: no time"))
    place_source: str | None = Field(None, description=(
        "where the place comes from: `given` (site_id or latitude/longitude), "
        "`calibration N (…)` (none given: the place calibration_id was fitted at), null: "
        "no place, no ephemeris"))
    site_id: str | None
    latitude_deg: float | None
    longitude_deg: float | None


class FisheyeCameraRead(BaseModel):
    """A fisheye camera model (``vision.cameras.FisheyeCamera``; seed 003, eqs. 9–11)."""

    projection: str
    cx_px: float
    cy_px: float
    px_per_deg: float
    north_offset_deg: float
    east: str = Field(description="`left` or `right`: the side east shows on")
    radial_coeffs: list[float]
    tilt_north_deg: float
    tilt_east_deg: float


class CalibrationFrameRead(BaseModel):
    """One frame of a calibration and its residual."""

    filename: str
    timestamp: str
    sun_found: bool
    confidence: float
    centroid_px: list[float] | None
    used: bool
    outlier: bool = Field(False, description="a sun found, but farther than 1° from the "
                                             "consensus of the others: left out of the fit")
    search: str | None = Field(None, description="`blind`, or `ephemeris-guided` (searched "
                                                 "where the first fit put the sun)")
    residual_px: float | None
    residual_deg: float | None
    ephemeris: EphemerisRead


class CalibrationSummaryRead(BaseModel):
    """A stored calibration in the list."""

    calibration_id: int
    name: str
    created_at: str
    site_id: str | None
    latitude_deg: float
    longitude_deg: float
    elevation_m: float
    projection: str
    image_size_px: list[int]
    n_frames: int
    rms_px: float
    max_px: float
    rms_deg: float
    max_deg: float
    camera: FisheyeCameraRead


class StoredCalibrationRead(CalibrationSummaryRead):
    """One stored calibration with its per-frame residuals."""

    frames: list[CalibrationFrameRead]


class CalibrationsRead(BaseModel):
    """Stored calibrations, newest first."""

    calibrations: list[CalibrationSummaryRead]


class RadialChoiceRead(BaseModel):
    """A camera model (projection and radial terms) tried on the fit's inlier frames and its
    leave-one-out error."""

    projection: str
    n_radial: int
    loo_rms_deg: float = Field(description="each of the stored fit's inlier frames against "
                                           "this model fitted without it (held out) [°]")
    n_inliers: int | None = Field(
        None, description="frames this model's own robust fit explains within 1° (the model "
                          "explaining the most decides the inliers); none for the "
                          "projections compared (projection=auto) on the equidistant "
                          "fit's inliers")


class FittedCalibrationRead(BaseModel):
    """A calibration just fitted and stored (201)."""

    calibration_id: int
    name: str
    site_id: str | None
    latitude_deg: float
    longitude_deg: float
    elevation_m: float
    projection: str
    cx_px: float
    cy_px: float
    px_per_deg: float
    north_offset_deg: float
    east: str
    tilt_north_deg: float
    tilt_east_deg: float
    image_width_px: int
    image_height_px: int
    n_frames: int
    rms_px: float
    max_px: float
    rms_deg: float
    max_deg: float
    n_outliers: int = Field(description="frames whose sun disagreed with the consensus")
    loo_rms_deg: float | None = Field(description="each inlier frame against the model "
                                                  "fitted without it (held out) [°]")
    model_selection: list[RadialChoiceRead]
    sky_uncertainty_deg: float = Field(
        description="how well the frames fix the camera away from their own suns: the "
                    "largest 1-σ error of the direction it gives a pixel over the sky from "
                    "the lowest fitted sun (fitted_elevation_deg, but not below 10°) up (the "
                    "fitted parameters' covariance propagated; "
                    "vision.calibrate.sky_uncertainty_deg); below that sun the lens is "
                    "extrapolated, and a warning says so when it is above 15° [°]")
    fitted_elevation_deg: list[float] = Field(
        description="the lowest and highest elevation of the suns the camera was fitted on "
                    "(its inliers) [°]: the band of the sky the frames measure")
    warnings: list[str] = Field(description="a calibration stored, but doubtful: frames "
                                            "that fix the camera poorly over the sky")
    frames: list[CalibrationFrameRead]
    camera: FisheyeCameraRead


class StoredDetectionRead(BaseModel):
    """A stored detection (fisheye: angles; pinhole: pointing error)."""

    detection_id: int
    timestamp: str | None
    created_at: str
    site_id: str | None
    latitude_deg: float | None
    longitude_deg: float | None
    camera: str
    calibration_id: int | None
    method: str
    image_size_px: list[int]
    sun_found: bool
    confidence: float
    centroid_px: list[float] | None
    azimuth_deg: float | None = None
    elevation_deg: float | None = None
    pointing_error_deg: list[float] | None = None
    pointing_error_mrad: float | None = None
    ephemeris: EphemerisRead | None = None
    error: SunErrorRead | None = None
    warnings: list[str]


class DetectionsRead(BaseModel):
    """Stored detections in [start, end)."""

    site_id: str | None
    start: str | None
    end: str | None
    detections: list[StoredDetectionRead]


class DetectionsDeletedRead(BaseModel):
    """How many stored detections were deleted."""

    site_id: str | None
    start: str
    end: str
    detections_deleted: int


class CalibrationDeletedRead(BaseModel):
    """A calibration deleted with the detections made with it."""

    calibration_id: int
    calibrations_deleted: int
    detections_deleted: int


class AxisErrorsRead(BaseModel):
    """Seed 003's Table 3 for one axis [°] (MSE [°²], MAPE [%])."""

    mad_deg: float
    mse_deg2: float
    rmse_deg: float
    mape_pct: float | None


class SeparationErrorsRead(BaseModel):
    """The angle between detected and ephemeris suns [°]."""

    mean_deg: float
    rmse_deg: float
    max_deg: float


class MethodMetricsRead(BaseModel):
    """Seed 003's Table 3 of one method."""

    azimuth: AxisErrorsRead
    elevation: AxisErrorsRead
    separation: SeparationErrorsRead


class MethodTableRead(BaseModel):
    """One detection method over the batch."""

    n_found: int
    n_frames: int
    metrics: MethodMetricsRead | None = Field(description="null when nothing was found")


class EvaluationRead(BaseModel):
    """Each method's angles against SPA: seed 003's Table 2 (per frame) and Table 3."""

    n_frames: int
    site_id: str | None
    latitude_deg: float
    longitude_deg: float
    camera: FisheyeCameraRead
    table2: list[dict[str, str | float | bool | None]] = Field(
        description="per frame: filename, timestamp, ephemeris_azimuth_deg, "
                    "ephemeris_elevation_deg and per method `<method>_sun_found`, "
                    "`<method>_azimuth_deg`, `<method>_elevation_deg`")
    table3: dict[str, MethodTableRead]


class FrameNameTimeRead(BaseModel):
    """The time a file name carries (``backend.vision.frames.time_from_name``)."""

    filename: str
    wall_time: str | None = Field(description="the name's date and time, ISO 8601 without "
                                              "offset; null: the name carries none")
    utc_offset_h: float | None = Field(description="the UTC offset the name states (`UTCp1` "
                                                   "→ 1, `UTC+05:30` → 5.5) [h]; null: none "
                                                   "stated")
    zone_error: str | None = Field(default=None, description="why the zone the name states "
                                   "cannot be read (then `wall_time` is null too: the frame "
                                   "needs its time sent); null: no problem")


class FrameTimesRead(BaseModel):
    """``GET /api/v1/vision/frame-times``: one entry per file name, in order."""

    frames: list[FrameNameTimeRead]

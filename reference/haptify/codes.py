# Generated from schemas/1.0/codes.json by `python -m haptify_tools.gen_docs`; do not edit by hand.
"""The codes of ``schemas/1.0/codes.json`` as names (spec §0.4): ``Code.SESSION_NOT_FOUND == "E101"``.

A member is a ``str`` (``StrEnum``), so it formats, compares, hashes and serialises as its code; the
catalogue stays the source of severity, title and hint (:func:`haptify.errors.catalogue`).
"""

from enum import StrEnum


class Code(StrEnum):
    """Every coded finding and error; the member name is the catalogue's ``name`` in upper case."""

    #: The session folder does not exist or is not a folder (§4.1)
    SESSION_NOT_FOUND = "E101"
    #: session.json is missing from the session folder (§3.1)
    MANIFEST_MISSING = "E102"
    #: session.json is not well-formed JSON (UTF-8) (§3.1)
    MANIFEST_MALFORMED_JSON = "E103"
    #: A field of a JSON document does not satisfy its schema (§2.1)
    SCHEMA_VIOLATION = "E104"
    #: The session declares a spec version this implementation does not support (§2.1)
    SPEC_VERSION_UNSUPPORTED = "E105"
    #: The device description file is missing, malformed or invalid (§2.3)
    DEVICE_FILE_INVALID = "E106"
    #: Two items share an id that must be unique (§2.5)
    DUPLICATE_ID = "E107"
    #: A file path is absolute or leaves the session folder (§3.3)
    UNSAFE_PATH = "E108"
    #: A file is a symbolic link that resolves outside the session folder (§3.3)
    SYMLINK_ESCAPE = "E109"
    #: A stream file named in session.json does not exist (§3.2)
    STREAM_FILE_MISSING = "E110"
    #: A stream file's sha256 differs from the one in session.json (§3.4)
    CHECKSUM_MISMATCH = "E111"
    #: A stream file cannot be read as its declared format (§3.2)
    STREAM_UNREADABLE = "E112"
    #: A declared size, count or rate is outside the limits of the spec (§3.5)
    DECLARED_SIZE_ABSURD = "E113"
    #: A record refers to a trial or stream file the session does not hold (§2.8)
    REFERENCE_UNKNOWN = "E114"
    #: A JSON document names the same member twice in one object (§3.1)
    JSON_DUPLICATE_KEY = "E117"
    #: A stream's columns are not those its kind requires (§2.6)
    COLUMN_MISMATCH = "E201"
    #: A column's unit is not the SI unit its kind requires (§2.6)
    WRONG_UNIT = "E202"
    #: The time column is missing, non-finite or not strictly increasing (§2.6)
    TIME_NOT_INCREASING = "E203"
    #: A column holds NaN where the spec does not allow it (§2.7)
    NAN_NOT_ALLOWED = "E204"
    #: A stream has fewer than two samples (§2.6)
    STREAM_EMPTY = "E205"
    #: The actual sample rate differs from the declared rate beyond the tolerance (§2.6)
    RATE_MISMATCH = "E206"
    #: A quaternion's norm differs from 1 beyond the tolerance (§1.3)
    QUATERNION_NOT_UNIT = "E207"
    #: The number of rows differs from the declared count (§3.5)
    ROW_COUNT_MISMATCH = "E208"
    #: A stream is declared in a frame its kind does not allow (§2.6)
    WRONG_FRAME = "E209"
    #: A column holds an infinite value (§2.7)
    NON_FINITE_VALUE = "E210"
    #: A CSV stream's header row is not the declared column list (§3.2)
    CSV_HEADER_MALFORMED = "E211"
    #: A column does not hold floating-point numbers, or the time column is not 64-bit (§3.2)
    COLUMN_NOT_NUMERIC = "E212"
    #: A stream names a marker or link the rig does not describe (§2.6)
    ENTITY_UNKNOWN = "E213"
    #: A trial names a protocol the spec does not define (§2.5)
    PROTOCOL_UNKNOWN = "E301"
    #: A trial lacks a stream its protocol requires (§2.5)
    REQUIRED_STREAM_MISSING = "E302"
    #: An active trial lacks its rendering parameters (§2.5)
    RENDERING_MISSING = "E303"
    #: A trial of protocol 'other' has no label (§2.5)
    LABEL_MISSING = "E304"
    #: The streams of one trial do not overlap in time (§2.6)
    STREAMS_DO_NOT_OVERLAP = "E305"
    #: A trial holds two streams of the same kind (§2.5)
    DUPLICATE_STREAM_KIND = "E306"
    #: Too little data to fit or judge the local dynamic model (§11.7)
    DYNAMICS_DATA_INSUFFICIENT = "E701"
    #: A Hammerstein-Wiener model parameter file is missing, malformed or invalid (§11.5)
    HW_MODEL_INVALID = "E702"
    #: Model inputs or outputs do not match the model (channel count, rate or non-finite values) (§11.3)
    HW_MODEL_DATA_MISMATCH = "E703"
    #: A reading lies outside the sensor range declared in the rig (§2.4)
    SENSOR_RANGE_EXCEEDED = "W401"
    #: Some sample intervals deviate strongly from the nominal interval (§2.6)
    SAMPLE_INTERVAL_IRREGULAR = "W402"
    #: The device's powered flag is unusual for the protocol (§2.5)
    POWERED_FLAG_UNUSUAL = "W403"
    #: A trial lacks a stream its protocol recommends (§2.5)
    RECOMMENDED_STREAM_MISSING = "W404"
    #: A large share of motion-capture samples is occluded (NaN) (§2.7)
    OCCLUSION_HIGH = "W405"
    #: A stream's rate is below the rate the spec recommends (§2.6)
    RATE_BELOW_RECOMMENDED = "W406"
    #: The file to import cannot be read (§5.1)
    IMPORT_SOURCE_UNREADABLE = "E501"
    #: The import mapping file is malformed or invalid (§5.2)
    IMPORT_MAP_INVALID = "E502"
    #: The mapping names a channel, label or column the source does not have (§5.2)
    IMPORT_CHANNEL_UNKNOWN = "E503"
    #: A unit in the source or mapping cannot be converted to SI (§5.2)
    IMPORT_UNIT_UNKNOWN = "E504"
    #: A force platform's corners or origin cannot define a plate frame (coincident, crossed, far from any rectangle, or not finite) (§5.6)
    IMPORT_PLATE_GEOMETRY_MEANINGLESS = "E505"
    #: A force platform's channels cannot give its wrench (type not 1–4, channels or calibration matrix missing or of the wrong size, type-3 sensor offsets zero, origin not finite) (§5.6)
    IMPORT_PLATFORM_WRENCH_UNREADABLE = "E506"
    #: The source file's header, parameters and data disagree; the data as read were imported (§5.5)
    IMPORT_SOURCE_DISAGREES = "W501"
    #: A force platform's corners are not exactly a flat rectangle; the best-fitting plate frame was used (§5.6)
    IMPORT_PLATE_NOT_RECTANGULAR = "W502"
    #: A force platform's ORIGIN follows the other sign convention; it was read by the rule of §5.6.1 (§5.6)
    IMPORT_PLATE_ORIGIN_SIGN = "W503"
    #: The simulator was asked for an effect, parameter or preset the device twin does not have (§0)
    TWIN_UNKNOWN_EFFECT = "E801"
    #: The device twin file cannot be read or does not match twin.schema.json (§0)
    TWIN_FILE_INVALID = "E802"
    #: A hand pose given to the simulator lies outside the device's reach (§0)
    TWIN_POSE_UNREACHABLE = "E803"
    #: The output path exists (§3.6)
    OUTPUT_EXISTS = "E901"
    #: The output cannot be written (§3.6)
    OUTPUT_NOT_WRITABLE = "E902"
    #: The command was called with invalid arguments (§0)
    USAGE = "E903"
    #: The viewer could not be started or did not answer (§0)
    VIEWER_UNAVAILABLE = "E904"
    #: A definition file's parameters do not match what the implementation declares for them (a key extra or missing, or a value of the wrong type) (§0.3)
    DEFINITION_PARAMETERS_INVALID = "E905"
    #: An unexpected internal error (§0)
    INTERNAL_ERROR = "E999"
    #: Neither a handle_gravity calibration record nor a rig.handle_calibration trial is available (§6.4)
    HANDLE_CALIBRATION_MISSING = "E601"
    #: The calibration data cannot determine the sphere fit (too few samples or orientations too narrow) (§6.2)
    HANDLE_CALIBRATION_DEGENERATE = "E602"
    #: The rig description lacks a part (handle sensor pose, force plate corners) needed to interpret a stream (§6.5)
    RIG_PART_MISSING = "E603"
    #: No usable motion-capture samples overlap the trial's other streams (§7.4)
    MOTION_CAPTURE_UNUSABLE = "E611"
    #: Neither a plate_bias calibration record nor a rig.plate_bias trial is available (§14.2)
    PLATE_BIAS_MISSING = "E621"
    #: The impact trial shows no spectral peak in the analysis band (§14.4)
    PLATE_IMPACT_NOT_FOUND = "E622"
    #: No static placements of the weight were found in the COP trial (§14.5)
    COP_PLACEMENTS_NOT_FOUND = "E623"
    #: The recorder delays cannot be determined from the calibration trial (the handle hardly rotated or the peak lies at the search edge) (§14.6)
    SYNC_UNDETERMINED = "E624"
    #: The session has no usable trial of the protocol a metric needs (§15.2)
    PROTOCOL_TRIALS_MISSING = "E310"
    #: The device description has no kinematic model, so the modeled workspace cannot be computed (§8.3)
    DEVICE_KINEMATICS_MISSING = "E311"
    #: The device datasheet lacks the figure a metric reports (§8.6)
    DATASHEET_VALUE_MISSING = "E312"
    #: A workspace point cloud has too few finite points or spans more than the voxel grid allows (§8.4)
    WORKSPACE_CLOUD_UNUSABLE = "E313"
    #: No sample of an active trial is in contact with the rendered surface (§12.2)
    NO_CONTACT = "E314"
    #: No press into the rendered surface qualifies for the stiffness fit (§13.2)
    NO_PRESSES = "E315"
    #: A signal is too short for the analysis after its edges are trimmed (§10.2)
    SIGNAL_TOO_SHORT = "E316"
    #: The sampled workspace boundary did not close into a solid; the volume is far too small to be trusted (§8.4)
    WORKSPACE_SHELL_OPEN = "W410"
    #: The examiner moved faster than the free-space protocol allows for a large share of the trial (§9.4)
    SPEED_ABOVE_PROTOCOL = "W411"
    #: The examiner rotated the handle faster than the free-space protocol allows for a large share of the trial (§9.4)
    ANGULAR_SPEED_ABOVE_PROTOCOL = "W412"
    #: A trial could not be used for a metric; the metric rests on the remaining repetitions (§15.3)
    TRIAL_SKIPPED = "W413"
    #: Fewer presses than recommended qualified for the stiffness fit (§13.2)
    FEW_PRESSES = "W414"
    #: A press had too few samples on its rise for the stiffness fit and was left out (§13.2)
    PRESS_TOO_FAST = "W415"
    #: The submission bundle, or what it unpacks to, exceeds the registry's size limits (§17.4)
    BUNDLE_TOO_LARGE = "E960"
    #: The submission is not a readable gzip-compressed tar archive (§17.2)
    BUNDLE_ARCHIVE_INVALID = "E961"
    #: An archive member is not a plain file at a safe relative path (absolute path, '..', link, device, duplicate) (§17.4)
    BUNDLE_UNSAFE_MEMBER = "E962"
    #: The archive expands far beyond its compressed size or beyond the registry's limit (§17.4)
    BUNDLE_DECOMPRESSION_BOMB = "E963"
    #: bundle.json is missing, not well-formed JSON or does not match the bundle schema (§17.2)
    BUNDLE_MANIFEST_INVALID = "E964"
    #: A file of the bundle is missing, undeclared, or its size or sha256 differs from bundle.json (§17.2)
    BUNDLE_FILE_MISMATCH = "E965"
    #: A document inside the bundle is invalid or contradicts another (results, conformance report, session manifest) (§17.3)
    BUNDLE_CONTENT_INVALID = "E966"
    #: No passing conformance report of the same implementation and spec version covers the submitted metrics (§17.3)
    CONFORMANCE_NOT_PASSING = "E967"
    #: The bundle is written for a spec version this registry does not accept (§17.2)
    BUNDLE_SPEC_VERSION_UNSUPPORTED = "E968"
    #: The API token is missing, malformed or unknown (§17.6)
    TOKEN_INVALID = "E970"
    #: The API token's scope does not allow this request (§17.6)
    TOKEN_SCOPE = "E971"
    #: The API token has made too many requests in the current minute (§17.6)
    RATE_LIMITED = "E972"
    #: The requested record (submission, device, lab) does not exist (§17.5)
    NOT_FOUND = "E973"
    #: The submission cannot be superseded or withdrawn (another lab's, already superseded or already withdrawn) (§17.5)
    SUPERSEDE_CONFLICT = "E974"
    #: The API request is malformed (parameters, body or content type) (§17.5)
    REQUEST_INVALID = "E975"
    #: Checking the bundle exceeded the memory or time limit of the registry's worker process (§17.4)
    BUNDLE_WORKER_LIMIT = "E976"
    #: The bundle's lab is not the lab of the API token (§17.6)
    LAB_MISMATCH = "E977"
    #: The registry could not store or read its records (database or data folder) (§17.7)
    REGISTRY_UNAVAILABLE = "E978"
    #: The conformance challenge has expired or has been answered already (an answer is judged once) (§17.8)
    CHALLENGE_CLOSED = "E979"
    #: The Dask scheduler given with --scheduler does not answer (§17.9)
    CLUSTER_UNAVAILABLE = "E980"
    #: A re-verification run started by another reference version cannot be resumed by this one (§17.9)
    REVERIFY_RUN_OF_ANOTHER_REFERENCE = "E981"
    #: A metric re-computed by the installed reference moved beyond its conformance tolerance from its previous re-computation (§17.9)
    REVERIFIED_VALUE_MOVED = "W982"
    #: A submitted metric differs from the reference's re-computation on the included raw streams beyond its tolerance (§17.3)
    METRIC_DISAGREES = "W969"
    #: A joint's upper limit lies below its lower limit for every configuration of the earlier joints, so the kinematic model admits no configuration (§2.3)
    JOINT_LIMITS_EMPTY = "E115"
    #: The device's kinematic chain breaks a rule of the format: joints named q1, q2, ... in chain order, limits depending only on earlier joints (§2.3)
    KINEMATIC_CHAIN_INVALID = "E116"
    #: A column holds a value outside the set its stream kind allows (the sync trigger is 0 or 1) (§2.6)
    VALUE_NOT_ALLOWED = "E214"
    #: A stream declares entities although its kind has none (only markers and link_poses have entities) (§2.6)
    ENTITIES_NOT_ALLOWED = "E215"
    #: A rendering's surface_normal is not a unit vector within the tolerance (§2.5)
    SURFACE_NORMAL_NOT_UNIT = "E307"
    #: An optional member is written as null instead of being omitted (§2.1)
    NULL_MEMBER = "W407"

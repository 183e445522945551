"""Fixed-layout ROS 2 CDR decoding of the few message types gpsdr reads, vectorised.

Why hand-written: ``mcap_ros2``'s generic decoder builds a Python object per
message (~40 k msg/s).  The messages gpsdr needs have a fixed layout once the
header's ``frame_id`` length is known, so a whole batch is decoded with numpy
gathers over the raw bytes (several M msg/s).  The layout is the OMG CDR v1
(XCDR1) rules ROS 2 uses: a 4-byte encapsulation header (``00 01`` = little
endian), then every primitive aligned to its own size counted from the end of
that header; strings are a uint32 length (including the NUL) and the bytes;
fixed arrays (``float64[9]``) have no length prefix.  The same layouts in ROS 1
serialisation (converted bags) differ only in framing: no encapsulation header,
no padding, a uint32 ``seq`` before the stamp, strings without the NUL.

Anything the fast path cannot vouch for (big-endian or parameter-list
encapsulation, a length that runs past the message, nanoseconds >= 1e9) is
returned with ``ok = False``; the caller decodes those with the generic
decoder.  Tests check both paths give the same values.

Layouts (q = offset after the 4-byte encapsulation header)::

    std_msgs/Header   q=0 int32 stamp.sec, q=4 uint32 stamp.nanosec,
                      q=8 uint32 L, q=12.. frame_id bytes; next q = 12 + L
    NavSatFix         int8 status, uint16 service (align 2), float64 lat, lon, alt
                      (align 8), float64[9] position_covariance, uint8 covariance_type
    Imu               Quaternion (4 f64), f64[9], angular_velocity (3 f64), f64[9], ...
    TwistStamped      Twist: linear (3 f64), angular (3 f64)
    TwistWithCovarianceStamped  Twist, f64[36]
    Odometry          Header, string child_frame_id, PoseWithCovariance (7 + 36 f64),
                      TwistWithCovariance
    nmea_msgs/Sentence  Header, string sentence
"""

from __future__ import annotations

import struct

import numpy as np

#: Schema names (ROS 2 and ROS 1 spellings) -> layout name.
LAYOUTS: dict[str, str] = {}
for _pkg, _name, _layout in (
        ("sensor_msgs", "NavSatFix", "navsatfix"),
        ("sensor_msgs", "Imu", "imu"),
        ("geometry_msgs", "TwistStamped", "twist"),
        ("geometry_msgs", "TwistWithCovarianceStamped", "twistcov"),
        ("nav_msgs", "Odometry", "odometry"),
        ("nmea_msgs", "Sentence", "sentence")):
    LAYOUTS[f"{_pkg}/msg/{_name}"] = _layout
    LAYOUTS[f"{_pkg}/{_name}"] = _layout

_AR2 = np.arange(2)
_AR4 = np.arange(4)
_AR8 = np.arange(8)


def _gather(buf: np.ndarray, pos: np.ndarray, width: np.ndarray, dtype: str) -> np.ndarray:
    """The ``dtype`` value at each byte position ``pos`` of ``buf`` (all in bounds)."""
    w = len(width)
    if len(buf) < w or len(pos) < 4096:  # small batches: the view costs more than it saves
        return buf[pos[:, None] + width].view(dtype)[:, 0]
    # rows of a (len - w + 1, w) byte-overlapping view: one index per value, not w
    rows = np.lib.stride_tricks.as_strided(buf, shape=(len(buf) - w + 1, w),
                                           strides=(buf.strides[0], buf.strides[0]),
                                           writeable=False)
    return rows[pos].view(dtype)[:, 0]


def _align(q: np.ndarray, n: int) -> np.ndarray:
    return (q + (n - 1)) & ~np.int64(n - 1)


class _Batch:
    """Bounds-checked gathers for one batch of messages in one buffer."""

    def __init__(self, buf: np.ndarray, off: np.ndarray, size: np.ndarray, ros1: bool) -> None:
        self.buf = buf
        self.ros1 = ros1
        self.base = 0 if ros1 else 4  # bytes before q = 0
        self.p0 = off.astype(np.int64) + self.base
        self.size = size.astype(np.int64)
        self.ok = self.size >= 16
        if not ros1:
            # Encapsulation: 00 01 is CDR little endian; anything else goes to the generic decoder.
            head = _gather(buf, np.where(self.ok, off, 0).astype(np.int64), _AR2, "<u2")
            self.ok &= head == 0x0100

    def al(self, q: np.ndarray, n: int) -> np.ndarray:
        """Align q to n bytes (CDR); ROS 1 serialisation has no padding."""
        return q if self.ros1 else _align(q, n)

    def need(self, q_end: np.ndarray | int) -> None:
        """Mark messages shorter than base + q_end bytes as not decodable here."""
        self.ok &= self.base + np.asarray(q_end, np.int64) <= self.size

    def _pos(self, q: np.ndarray | int, width: int) -> np.ndarray:
        q = np.asarray(q, np.int64)
        good = self.ok & (self.base + q + width <= self.size)
        return np.where(good, self.p0 + q, 0)

    def u8(self, q: np.ndarray | int) -> np.ndarray:
        return self.buf[self._pos(q, 1)]

    def i8(self, q: np.ndarray | int) -> np.ndarray:
        return self.buf[self._pos(q, 1)].view(np.int8)

    def u32(self, q: np.ndarray | int) -> np.ndarray:
        return _gather(self.buf, self._pos(q, 4), _AR4, "<u4").astype(np.int64)

    def i32(self, q: np.ndarray | int) -> np.ndarray:
        return _gather(self.buf, self._pos(q, 4), _AR4, "<i4").astype(np.int64)

    def f64(self, q: np.ndarray | int) -> np.ndarray:
        return _gather(self.buf, self._pos(q, 8), _AR8, "<f8")

    def string_end(self, q: np.ndarray) -> np.ndarray:
        """q after a string whose uint32 length is at align4(q)."""
        q = self.al(q, 4)
        self.need(q + 4)
        n = self.u32(q)
        self.need(q + 4 + n)
        return q + 4 + n

    def header(self) -> tuple[np.ndarray, np.ndarray]:
        """(stamp in int64 ns, q after the header).

        ROS 2: int32 sec, uint32 nanosec, frame_id.  ROS 1: uint32 seq, uint32 sec,
        uint32 nsec, frame_id (length without a NUL)."""
        k = 4 if self.ros1 else 0
        sec = self.u32(k) if self.ros1 else self.i32(0)
        nsec = self.u32(k + 4)
        self.ok &= nsec < 1_000_000_000
        q = self.string_end(np.full(len(self.p0), k + 8, np.int64))
        return sec * 1_000_000_000 + nsec, q


def decode(layout: str, buf: np.ndarray, off: np.ndarray, size: np.ndarray, *, ros1: bool = False
           ) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Decode messages ``buf[off[i]:off[i]+size[i]]`` of one layout.

    Returns ``(fields, ok)``: field arrays of len(off) (meaningless where not ok)
    and the mask of messages decoded here.  Fields: ``stamp_ns`` always; then
    navsatfix: ``status``, ``lat``, ``lon``, ``alt``, ``cov_e``, ``cov_n`` (the
    covariance diagonal's east and north terms, m^2), ``cov_type``; imu: ``wz``
    (angular_velocity.z, rad/s), ``wz_cov0`` (angular_velocity_covariance[0]), ``ax``
    (linear_acceleration.x, m/s^2), ``ax_cov0`` (linear_acceleration_covariance[0]);
    twist/twistcov/odometry: ``vx``, ``vy`` (twist.linear, m/s); sentence:
    ``text_off``, ``text_len`` (the sentence bytes in ``buf``, NUL excluded).
    ``ros1``: the ROS 1 serialisation (same field order, no encapsulation
    header, no alignment, a ``seq`` before the stamp, strings without a NUL).
    """
    b = _Batch(buf, np.asarray(off, np.int64), np.asarray(size, np.int64), ros1)
    stamp_ns, q = b.header()
    out: dict[str, np.ndarray] = {"stamp_ns": stamp_ns}
    if layout == "navsatfix":
        q_service = b.al(q + 1, 2)
        q_lat = b.al(q_service + 2, 8)
        b.need(q_lat + 97)
        out["status"] = b.i8(q)
        out["lat"] = b.f64(q_lat)
        out["lon"] = b.f64(q_lat + 8)
        out["alt"] = b.f64(q_lat + 16)
        out["cov_e"] = b.f64(q_lat + 24)          # position_covariance[0]
        out["cov_n"] = b.f64(q_lat + 24 + 32)     # position_covariance[4]
        out["cov_type"] = b.u8(q_lat + 96)
    elif layout == "imu":
        q_av = b.al(q, 8) + 104                 # after orientation (4 f64) and its f64[9]
        b.need(q_av + 24 + 72 + 24 + 72)
        out["wz"] = b.f64(q_av + 16)
        out["wz_cov0"] = b.f64(q_av + 24)
        out["ax"] = b.f64(q_av + 96)              # linear_acceleration.x
        out["ax_cov0"] = b.f64(q_av + 120)        # linear_acceleration_covariance[0]
    elif layout in ("twist", "twistcov", "odometry"):
        if layout == "odometry":
            q = b.string_end(q)                   # child_frame_id
            q_lin = b.al(q, 8) + 344            # after PoseWithCovariance (7 + 36 f64)
            extra = 288
        else:
            q_lin = b.al(q, 8)
            extra = 288 if layout == "twistcov" else 0
        b.need(q_lin + 48 + extra)
        out["vx"] = b.f64(q_lin)
        out["vy"] = b.f64(q_lin + 8)
    elif layout == "sentence":
        q_s = b.al(q, 4)
        b.need(q_s + 4)
        n = b.u32(q_s)
        b.need(q_s + 4 + n)
        out["text_off"] = b.p0 + q_s + 4
        out["text_len"] = n if ros1 else np.maximum(n - 1, 0)
    else:
        raise ValueError(f"unknown layout {layout!r}")
    return out, b.ok


# --------------------------------------------------------------------------- encoding

_TIME = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
_HEADER = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
_VECTOR3 = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"
_QUAT = "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
_TWIST = "MSG: geometry_msgs/Twist\nVector3 linear\nVector3 angular\n"
_TWISTCOV = "MSG: geometry_msgs/TwistWithCovariance\nTwist twist\nfloat64[36] covariance\n"
_POINT = "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n"
_POSE = "MSG: geometry_msgs/Pose\nPoint position\nQuaternion orientation\n"
_POSECOV = "MSG: geometry_msgs/PoseWithCovariance\nPose pose\nfloat64[36] covariance\n"
_STATUS = ("MSG: sensor_msgs/NavSatStatus\nint8 STATUS_NO_FIX = -1\nint8 STATUS_FIX = 0\n"
           "int8 STATUS_SBAS_FIX = 1\nint8 STATUS_GBAS_FIX = 2\nint8 status\nuint16 service\n")
_SEP = "=" * 80 + "\n"


def _msgdef(main: str, *deps: str) -> str:
    return main + "".join(_SEP + d for d in deps)


#: layout -> (ROS 2 schema name, concatenated message definition) for writing MCAPs.
SCHEMAS: dict[str, tuple[str, str]] = {
    "navsatfix": ("sensor_msgs/msg/NavSatFix", _msgdef(
        "std_msgs/Header header\nNavSatStatus status\nfloat64 latitude\nfloat64 longitude\n"
        "float64 altitude\nfloat64[9] position_covariance\nuint8 position_covariance_type\n",
        _HEADER, _STATUS, _TIME)),
    "imu": ("sensor_msgs/msg/Imu", _msgdef(
        "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\n"
        "float64[9] orientation_covariance\ngeometry_msgs/Vector3 angular_velocity\n"
        "float64[9] angular_velocity_covariance\ngeometry_msgs/Vector3 linear_acceleration\n"
        "float64[9] linear_acceleration_covariance\n", _HEADER, _QUAT, _VECTOR3, _TIME)),
    "twist": ("geometry_msgs/msg/TwistStamped", _msgdef(
        "std_msgs/Header header\nTwist twist\n", _HEADER, _TWIST, _VECTOR3, _TIME)),
    "twistcov": ("geometry_msgs/msg/TwistWithCovarianceStamped", _msgdef(
        "std_msgs/Header header\nTwistWithCovariance twist\n",
        _HEADER, _TWISTCOV, _TWIST, _VECTOR3, _TIME)),
    "odometry": ("nav_msgs/msg/Odometry", _msgdef(
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n"
        "geometry_msgs/TwistWithCovariance twist\n",
        _HEADER, _POSECOV, _POSE, _POINT, _QUAT, _TWISTCOV, _TWIST, _VECTOR3, _TIME)),
    "sentence": ("nmea_msgs/msg/Sentence", _msgdef(
        "std_msgs/Header header\nstring sentence\n", _HEADER, _TIME)),
}


class _CdrWriter:
    """Little-endian CDR v1 with alignment counted after the 4-byte header (or ROS 1)."""

    def __init__(self, ros1: bool) -> None:
        self.ros1 = ros1
        self.out = bytearray() if ros1 else bytearray(b"\x00\x01\x00\x00")

    def _pad(self, n: int) -> None:
        if not self.ros1:
            self.out.extend(b"\x00" * (-(len(self.out) - 4) % n))

    def put(self, fmt: str, *values: float) -> None:
        self._pad(struct.calcsize("<" + fmt.lstrip("0123456789")[0]))
        self.out.extend(struct.pack("<" + fmt, *values))

    def string(self, text: str | bytes) -> None:
        raw = text.encode("utf-8") if isinstance(text, str) else text
        if self.ros1:
            self.put("I", len(raw))
            self.out.extend(raw)
        else:
            self.put("I", len(raw) + 1)
            self.out.extend(raw + b"\x00")


def encode(layout: str, stamp_ns: int, frame_id: str = "", *, ros1: bool = False,
           **f: float | str | bytes) -> bytes:
    """Serialise one message of ``layout`` (the inverse of :func:`decode`), for tests,
    benchmarks and simulated logs.  Keywords: navsatfix ``status, service, lat, lon,
    alt, cov (9 floats), cov_type``; imu ``wz, wz_cov0, ax``; twist/twistcov/odometry
    ``vx, vy``, odometry ``child_frame_id``; sentence ``text``.  ``ros1``: ROS 1
    serialisation (``seq`` = 0)."""
    w = _CdrWriter(ros1)
    if ros1:
        w.put("I", 0)
    w.put("II" if ros1 else "iI", *divmod(int(stamp_ns), 1_000_000_000))
    w.string(frame_id)
    if layout == "navsatfix":
        w.put("b", int(f.get("status", 0)))
        w.put("H", int(f.get("service", 1)))
        cov = f.get("cov", (0.0,) * 9)
        w.put("3d", float(f["lat"]), float(f["lon"]), float(f.get("alt", 0.0)))
        w.put("9d", *cov)  # type: ignore[arg-type]
        w.put("B", int(f.get("cov_type", 0)))
    elif layout == "imu":
        w.put("4d", 0.0, 0.0, 0.0, 1.0)
        w.put("9d", *(0.0,) * 9)
        w.put("3d", 0.0, 0.0, float(f["wz"]))
        w.put("9d", float(f.get("wz_cov0", 0.0)), *(0.0,) * 8)
        w.put("3d", float(f.get("ax", 0.0)), 0.0, 9.81)
        w.put("9d", *(0.0,) * 9)
    elif layout in ("twist", "twistcov", "odometry"):
        if layout == "odometry":
            w.string(str(f.get("child_frame_id", "base_link")))
            w.put("7d", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
            w.put("36d", *(0.0,) * 36)
        w.put("6d", float(f["vx"]), float(f.get("vy", 0.0)), 0.0, 0.0, 0.0, float(f.get("wz", 0.0)))
        if layout != "twist":
            w.put("36d", *(0.0,) * 36)
    elif layout == "sentence":
        w.string(f["text"])  # type: ignore[arg-type]
    else:
        raise ValueError(f"unknown layout {layout!r}")
    return bytes(w.out)

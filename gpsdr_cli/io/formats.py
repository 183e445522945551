"""File magics and sync bytes, for sniffing a file's format without importing its reader."""

from __future__ import annotations

#: The MCAP file magic (and its closing magic).
MCAP_MAGIC = b"\x89MCAP0\r\n"
PARQUET_MAGIC = b"PAR1"
#: u-blox UBX frame sync characters (mu, b).
UBX_SYNC = b"\xb5\x62"
#: ROS 1 bag version line; ROS 2 bags are SQLite 3 databases.
ROSBAG1_MAGIC = b"#ROSBAG V2.0\n"
SQLITE_MAGIC = b"SQLite format 3\x00"

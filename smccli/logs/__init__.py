"""MCAP logs: topics and codecs (``topics``), crash-safe writing (``writer``), checked reading
(``reader``). See docs/design.md section 3 for the layout."""

from smccli.logs.log import Log, PointCloudMsg, Scan
from smccli.logs.reader import read_log
from smccli.logs.rewrite import log_summary, strip_topic
from smccli.logs.topics import JSON_TOPICS, PROTO_TOPICS
from smccli.logs.writer import LogWriter, part_path

__all__ = [
    "JSON_TOPICS",
    "Log",
    "LogWriter",
    "PROTO_TOPICS",
    "PointCloudMsg",
    "Scan",
    "log_summary",
    "part_path",
    "read_log",
    "strip_topic",
]

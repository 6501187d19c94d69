"""ROS 2 bags and MCAP logs: the reader lives in :mod:`jflex.data`; re-exported here."""

from ..data._rosbag import MSGTYPE as MSGTYPE, TOPIC as TOPIC, read_rosbag as read_rosbag
from ..data._rosbag import rosbag_arrays as rosbag_arrays

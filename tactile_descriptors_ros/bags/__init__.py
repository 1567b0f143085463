"""Bags: rosbag2 (mcap, sqlite3) writing, reading, import, record, replay and echo support.

The pure parts (type store, bag I/O, QoS bookkeeping, message summaries,
import of the BioTac recordings) need rosbags and numpy only; recording,
replaying and live echo import rclpy when used.
"""

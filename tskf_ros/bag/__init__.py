"""Recorded bags: rosbag2 MCAP (and sqlite3) reading and writing, record, play, offline replay."""

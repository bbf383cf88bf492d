"""Tests of tskf_ros.bag.replay, one file per module."""

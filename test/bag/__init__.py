"""Tests of tskf_ros.bag, one file per module."""

# Copyright 2026 The tskf_ros authors
# SPDX-License-Identifier: Apache-2.0
"""
LED alignment in two axes: a pan-tilt receiver, a conical-scan EKF, and its closed loop.

pointing_geometry (the mount, the sphere and the tangent plane), radial_response (the
one-axis response of Solanki et al. as a function of the off-axis angle), conical_ekf
(the EKF and its per-axis P law) and pan_tilt_simulation (the closed loop on the sphere).
"""

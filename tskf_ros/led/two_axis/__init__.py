# Copyright 2026 The tskf_ros authors
# SPDX-License-Identifier: Apache-2.0
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
LED alignment in two axes: a pan-tilt receiver, a conical-scan EKF, its supervisor and loop.

pointing_geometry (the mount, the sphere and the tangent plane), radial_response (the
one-axis response of Solanki et al. as a function of the off-axis angle), conical_ekf
(the EKF, its per-axis P law and LQR), pan_tilt_link (the link as a seeded plant),
pan_tilt_simulation (the closed loop, vectorised over runs), spiral_search, spot_detector
and pan_tilt_supervisor (acquiring, tracking, lost), aligners (each aligner by name) and
pan_tilt_session (one sample at a time, for the node).  Design: doc/design/two_axis.md.
"""

# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The fitting engine: parameters, likelihood, least squares and their uncertainty (no
physics). A regular package, so that setup.py's find_packages installs it."""

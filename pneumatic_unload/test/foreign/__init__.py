# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers

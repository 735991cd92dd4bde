"""Shared pytest fixtures. ROS process helpers live in ros_helpers.py (see its docstring).

- ``ros_domain``: a ROS_DOMAIN_ID reserved for one test (no other cooperating test process on
  the machine uses it while the test runs); pass it to ros_helpers.spawn_* / ros_env.
"""

import pytest
from ros_helpers import allocate_domain, release_domain


@pytest.fixture
def ros_domain():
    domain = allocate_domain()
    try:
        yield domain
    finally:
        release_domain(domain)

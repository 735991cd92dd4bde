"""``colcon test``: this package's package.xml and install (tmgwr_common.package_checks)."""

from pathlib import Path

from tmgwr_common.package_checks import check_package


def test_package_xml_and_install():
    check_package(Path(__file__).absolute().parents[1])

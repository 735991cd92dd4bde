from setuptools import find_packages, setup

package_name = "tmgwr_common"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="TMGWR maintainers",
    maintainer_email="tmgwr@example.com",
    description="Parameters, names, QoS and node main loop shared by maze_sim and tmgwr_agent.",
    license="Apache-2.0",
    extras_require={"test": ["pytest"]},
)

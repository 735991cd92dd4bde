from glob import glob

from setuptools import find_packages, setup

package_name = "maze_sim"

data_files = [
    ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
    # the parameter declarations of this package's nodes (tmgwr_common.params registry)
    ("share/ament_index/resource_index/tmgwr_parameters",
     ["resource/tmgwr_parameters/" + package_name]),
    ("share/" + package_name, ["package.xml"]),
    ("share/" + package_name + "/mazes", sorted(glob("mazes/*.txt"))),
]

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=data_files,
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="TMGWR maintainers",
    maintainer_email="tmgwr@example.com",
    description="Grid-world maze of the TMGWR experiments and its ROS 2 simulator node.",
    license="Apache-2.0",
    extras_require={"test": ["pytest"]},
    entry_points={
        "console_scripts": [
            "maze_sim = maze_sim.node:main",
        ],
    },
)

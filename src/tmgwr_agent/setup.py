import os
from glob import glob

from setuptools import find_packages, setup

package_name = "tmgwr_agent"


def _files(pattern):
    return sorted(f for f in glob(pattern) if os.path.isfile(f))


data_files = [
    ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
    # the parameter declarations of this package's nodes (tmgwr_common.params registry)
    ("share/ament_index/resource_index/tmgwr_parameters",
     ["resource/tmgwr_parameters/" + package_name]),
    ("share/" + package_name, ["package.xml"]),
    ("share/" + package_name + "/launch", _files("launch/*.py")),
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
    description="TMGWR goal-directed agent: core, ROS 2 nodes, recorder and experiment CLI.",
    license="Apache-2.0",
    extras_require={"test": ["pytest"]},
    entry_points={
        "console_scripts": [
            "sensory_preprocessor = tmgwr_agent.nodes.sensory_preprocessor:main",
            "map_learner = tmgwr_agent.nodes.map_learner:main",
            "motivation_estimator = tmgwr_agent.nodes.motivation_estimator:main",
            "action_selector = tmgwr_agent.nodes.action_selector:main",
            "recorder = tmgwr_agent.nodes.recorder:main",
            "composed = tmgwr_agent.nodes.composed:main",
        ],
    },
)

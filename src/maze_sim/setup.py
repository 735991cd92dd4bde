from glob import glob
import os

from setuptools import find_packages, setup

package_name = 'maze_sim'

data_files = [
    ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
    ('share/' + package_name, ['package.xml']),
]
# Mazes ship with the package when present (package-local first, else the repository's config/).
for mazes in ('config/mazes', os.path.join('..', '..', 'config', 'mazes')):
    files = sorted(f for f in glob(os.path.join(mazes, '*')) if os.path.isfile(f))
    if files:
        data_files.append((os.path.join('share', package_name, 'mazes'), files))
        break

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=data_files,
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='TMGWR maintainers',
    maintainer_email='tmgwr@example.com',
    description='Grid-world maze of the TMGWR experiments and its ROS 2 simulator node.',
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'maze_sim = maze_sim.node:main',
        ],
    },
)

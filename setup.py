from glob import glob

from setuptools import find_packages, setup

package_name = 'pattern_locator'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml') + glob('config/*.xml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='pattern_locator maintainers',
    maintainer_email='maintainers@pattern-locator.invalid',
    description='Robot self-location in a building from colour-dot cards and one camera.',
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'pattern-locator = pattern_locator.cli:main',
            'locator = pattern_locator.nodes.locator_node:main',
            'camera_driver = pattern_locator.nodes.camera_driver_node:main',
            'sim = pattern_locator.nodes.sim_node:main',
        ],
    },
)

from setuptools import find_packages, setup

package_name = 'tentacle_rig'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/launch', ['launch/rig.launch.py']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='Tentacle rig software team',
    maintainer_email='rig-software@example.com',
    description='The rig as a whole: process table and bringup, recorder, the lab facade, '
                'the navigation demo.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'rig = tentacle_rig.rig_cli:main',
            'rig_command = tentacle_rig.command_node:main',
            'recorder_node = tentacle_rig.recorder_node:main',
        ],
    },
)

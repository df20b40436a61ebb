from setuptools import find_packages, setup

package_name = 'tentacle_vision'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='Tentacle rig software team',
    maintainer_email='rig-software@example.com',
    description='Image pipeline, camera source and tentacle tracker.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'camera_node = tentacle_vision.camera_node:main',
            'tracker_node = tentacle_vision.tracker_node:main',
            'calibrate_camera = tentacle_vision.calibrate:main',
        ],
    },
)

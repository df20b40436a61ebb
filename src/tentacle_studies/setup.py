from setuptools import find_packages, setup

package_name = 'tentacle_studies'

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
    description='Design studies: study files, equilibria in batch, results tables (pure, no '
                'rclpy).',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'tentacle-sweep = tentacle_studies.sweep_cli:main',
            'tentacle-inverse = tentacle_studies.inverse_cli:main',
        ],
    },
)

from setuptools import find_packages, setup

package_name = 'tentacle_common'

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
    description='What every driver shares: parameter tables, signal-safe spin, logging, '
                'diagnostics, serial line with deadlines, retries.',
    license='Apache-2.0',
    tests_require=['pytest'],
)

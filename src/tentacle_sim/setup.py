from setuptools import find_packages, setup

package_name = 'tentacle_sim'

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
    description='Device emulators on pseudo-terminals and the simulated rig.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'sim_node = tentacle_sim.sim_node:main',
            'supply_emulator = tentacle_sim.emulate_supplies:main',
            'stage_emulator = tentacle_sim.emulate_stages:main',
        ],
    },
)

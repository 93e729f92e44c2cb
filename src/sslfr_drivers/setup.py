from setuptools import find_packages, setup

package_name = 'sslfr_drivers'

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
    maintainer='SSLFR tracker maintainers',
    maintainer_email='maintainers@sslfr-tracker.org',
    description='SSLFR board links, axis and sensor drivers, firmware build and flash',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'axis_driver = sslfr_drivers.axis.axis_driver_node:main',
            'lifecycle_ctl = sslfr_drivers.axis.lifecycle_ctl:main',
            'xbee_hub = sslfr_drivers.link.xbee_hub:main',
            'gps = sslfr_drivers.sensors.gps_node:main',
            'absorber_board = sslfr_drivers.sensors.absorber_board_node:main',
            'irradiance = sslfr_drivers.sensors.irradiance_node:main',
        ],
    },
)

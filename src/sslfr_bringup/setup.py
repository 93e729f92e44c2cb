from glob import glob

from setuptools import find_packages, setup

package_name = 'sslfr_bringup'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/config/collectors', glob('config/collectors/*.yaml')),
        ('share/' + package_name + '/config/fields', glob('config/fields/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='SSLFR tracker maintainers',
    maintainer_email='maintainers@sslfr-tracker.org',
    description='SSLFR bringup: node set, launch file, site configs, supervisor, the sslfr command',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'sslfr = sslfr_bringup.cli:main',
            'composed = sslfr_bringup.composed:main',
            'liveness_watchdog = sslfr_bringup.watchdog:main',
        ],
    },
)

from setuptools import find_packages, setup

package_name = 'sslfr_gateway'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', ['config/foxglove_layout.json']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='SSLFR tracker maintainers',
    maintainer_email='maintainers@sslfr-tracker.org',
    description='SSLFR plant gateway: SunSpec over Modbus TCP and Foxglove live',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'modbus_gateway = sslfr_gateway.modbus_node:main',
            'foxglove_bridge = sslfr_gateway.foxglove_node:main',
        ],
    },
)

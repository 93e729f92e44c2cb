from setuptools import find_packages, setup

package_name = 'sslfr_sim'

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
    description='SSLFR simulation: board simulators, firmware in the loop, simulated days, sslfr sim',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'sim_board = sslfr_sim.runner:main',
            'fw_board = sslfr_sim.fw_board:main',
        ],
    },
)

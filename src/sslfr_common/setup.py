from setuptools import find_packages, setup

package_name = 'sslfr_common'

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
    description='SSLFR node runtime: contract constants, parameter tables, node plumbing, executor',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
        ],
    },
)

from setuptools import find_packages, setup

package_name = 'sslfr_web'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={package_name: ['static/*']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=False,   # the operator page serves static/* from the package directory
    maintainer='SSLFR tracker maintainers',
    maintainer_email='maintainers@sslfr-tracker.org',
    description='SSLFR operator page: web node, live state, commands, login, recorded days',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'web = sslfr_web.web_node:main',
        ],
    },
)

from setuptools import find_packages, setup

package_name = 'sslfr_field'

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
    zip_safe=False,
    maintainer='SSLFR tracker maintainers',
    maintainer_email='maintainers@sslfr-tracker.org',
    description='SSLFR field: field descriptions, the operations station (discovery servers, field recorder)',
    license='Apache-2.0',
    entry_points={'console_scripts': ['field_page = sslfr_field.page_node:main']},
)

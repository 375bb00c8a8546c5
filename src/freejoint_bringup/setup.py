from setuptools import find_packages, setup

package_name = 'freejoint_bringup'

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
    maintainer='freejoint developers',
    maintainer_email='dev@freejoint.invalid',
    description='The simulator, controller and planner nodes in one process.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'graph = freejoint_bringup.graph:main',
        ],
    },
)

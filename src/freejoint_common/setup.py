from setuptools import find_packages, setup

package_name = 'freejoint_common'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools', 'numpy'],
    zip_safe=True,
    maintainer='freejoint developers',
    maintainer_email='dev@freejoint.invalid',
    description='Node plumbing shared by the freejoint nodes.',
    license='Apache-2.0',
    tests_require=['pytest'],
)

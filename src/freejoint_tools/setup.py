from setuptools import find_packages, setup

package_name = 'freejoint_tools'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools', 'numpy', 'mcap', 'rosbags', 'matplotlib', 'PyYAML'],
    zip_safe=True,
    maintainer='freejoint developers',
    maintainer_email='dev@freejoint.invalid',
    description='Record runs to MCAP rosbag2 bags, play them back, analyse them offline.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'recorder = freejoint_tools.recorder:main',
            'player = freejoint_tools.player:main',
            'analyze = freejoint_tools.analyze:main',
            'reindex = freejoint_tools.reindex:main',
            'fj = freejoint_tools.cli:main',
            'viewer = freejoint_tools.viewer:main',
            'campaign = freejoint_tools.campaign:main',
        ],
    },
)

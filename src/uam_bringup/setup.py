from glob import glob

from setuptools import find_packages, setup

package_name = "uam_bringup"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="UAM traffic management team",
    maintainer_email="uam@example.org",
    description="The rclpy glue of the UAM node graph (QoS profiles, parameter declaration, runtime, journal) and its launch file.",
    license="Apache-2.0",
)

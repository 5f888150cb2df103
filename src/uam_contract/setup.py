from setuptools import find_packages, setup

package_name = "uam_contract"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="UAM traffic management team",
    maintainer_email="uam@example.org",
    description="The contract of the UAM node graph: names, QoS specs, wire limits, stamps, parameter tables.",
    license="Apache-2.0",
    entry_points={"console_scripts": ["params_doc = uam_contract.params:main"]},
)

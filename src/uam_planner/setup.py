from setuptools import find_packages, setup

package_name = "uam_planner"

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
    description="Strategic deconfliction core and the planner node.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "planner = uam_planner.nodes.planner_node:main",
            "bench = uam_planner.bench:main",
        ],
    },
)

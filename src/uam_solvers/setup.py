from setuptools import find_packages, setup

package_name = "uam_solvers"

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
    description="MWIS backends, layers, TTS study and the solver node.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "solver = uam_solvers.nodes.solver_node:main",
            "backends = uam_solvers.registry:main",
            "tts = uam_solvers.tts:main",
            "bench = uam_solvers.bench:main",
        ],
        # Third-party packages add MWIS backends under this group (name = backend name,
        # value = "module:BackendClass"); the built-in ones live in uam_solvers.registry.
        "uam_solvers.backends": [],
    },
)

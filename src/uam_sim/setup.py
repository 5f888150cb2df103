from setuptools import find_packages, setup

package_name = "uam_sim"

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
    description="Request generator, simulator, recording, replay, analysis and experiments.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "request_generator = uam_sim.nodes.request_generator_node:main",
            "simulator = uam_sim.nodes.simulator_node:main",
            "recorder = uam_sim.nodes.recorder_node:main",
            "replay = uam_sim.nodes.replay_node:main",
            "conformance_monitor = uam_sim.nodes.conformance_node:main",
            "uss = uam_sim.nodes.uss_node:main",
            "export_f3548 = uam_sim.f3548.export_f3548:main",
            "analyze = uam_sim.audit.analysis:main",
            "experiment = uam_sim.studies.experiment:main",
        ],
        # uam_solvers.instances reads .mcap corpora through this (it cannot import uam_sim)
        "uam_solvers.corpus_readers": ["mcap = uam_sim.recording.recorded_instances:corpus_entries"],
    },
)

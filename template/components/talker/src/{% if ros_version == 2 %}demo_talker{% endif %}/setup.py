from setuptools import setup

package_name = "demo_talker"

setup(
    name=package_name,
    version="0.1.0",
    packages=[package_name],
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    tests_require=["pytest"],
    maintainer="robot developer",
    maintainer_email="dev@example.com",
    description="Example component: publishes a counting greeting on /chatter every 0.5 s.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "talker = demo_talker.talker:main",
        ],
    },
)

from setuptools import setup

package_name = "demo_listener"

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
    description="Example component: prints every message it hears on /chatter.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "listener = demo_listener.listener:main",
        ],
    },
)

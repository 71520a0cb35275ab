from setuptools import setup

package_name = "demo_server"

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
    maintainer="robot developer",
    maintainer_email="dev@example.com",
    description="Offers the greeting service and publishes greetings.",
    license="Apache-2.0",
    entry_points={"console_scripts": ["server = demo_server.server:main"]},
)

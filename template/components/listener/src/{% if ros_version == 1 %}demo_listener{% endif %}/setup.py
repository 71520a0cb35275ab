"""The Python package demo_listener, installed by catkin_python_setup() (not by pip)."""

from catkin_pkg.python_setup import generate_distutils_setup
from setuptools import setup

setup(**generate_distutils_setup(packages=["demo_listener"], package_dir={"": "src"}))

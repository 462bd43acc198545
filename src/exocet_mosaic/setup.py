# Python modules of exocet_mosaic (the helpers shared by its Python tests), installed by catkin_python_setup().
from catkin_pkg.python_setup import generate_distutils_setup
from setuptools import setup

setup(**generate_distutils_setup(packages=['exocet_mosaic'], package_dir={'': 'python'}))

"""For colcon (package.xml, build type ament_python): the project is described in pyproject.toml.

colcon reads a package's setup data as the repr of its attributes, which
it cannot parse for `requires-python` (a SpecifierSet): that one is given
back as text. `pip install` does not use this file's data files.
"""

from setuptools import setup

distribution = setup(data_files=[('share/ament_index/resource_index/packages', ['resource/bagfault']),
                                 ('share/bagfault', ['package.xml'])])
for holder in (distribution, distribution.metadata):
    if getattr(holder, 'python_requires', None) is not None:
        holder.python_requires = str(holder.python_requires)

"""
Message definitions for the bag: the full ``ros2msg`` text of a type and its RIHS01 hash.

The standard ROS 2 Jazzy types come from rosbags' Jazzy type store. Types it does not know
(this workspace's ``freejoint_msgs``, or any other package) are registered from their
``.msg`` files in the package's installed share directory (``share/<pkg>/msg/<Type>.msg``,
found through the ament index as ``ros2 bag record`` does), dependencies first. The text
written to the bag is the type store's normalised definition followed by one
``MSG: pkg/Type`` section per dependency, which every rosbag2/MCAP reader understands.
"""

import importlib
import os
import re

from rosbags.typesys import get_types_from_msg, get_typestore, Stores

_TYPE = re.compile(r'^([A-Za-z_][A-Za-z0-9_]*)/(msg)/([A-Za-z_][A-Za-z0-9_]*)$')


class DefinitionError(Exception):
    """A type whose definition cannot be found or parsed (message names the type)."""


def message_class(typename):
    """
    Return the Python class of a ROS 2 interface type (message or service).

    Parameters
    ----------
    typename : str
        ``'<package>/msg/<Type>'`` or ``'<package>/srv/<Type>'``.

    Returns
    -------
    type
        The class from the package's generated Python module.

    """
    pkg, kind, name = typename.split('/')
    return getattr(importlib.import_module('%s.%s' % (pkg, kind)), name)


def _share_dir(package):
    try:
        from ament_index_python.packages import (get_package_share_directory,
                                                 PackageNotFoundError)
    except ImportError:  # pragma: no cover - ament_index_python ships with rclpy
        raise DefinitionError('%s: ament_index_python is not available' % package)
    try:
        return get_package_share_directory(package)
    except (PackageNotFoundError, ValueError, LookupError):
        raise DefinitionError('package %s is not installed (not in the ament index)' % package)


class Definitions:
    """Definitions of message types, looked up once and cached."""

    def __init__(self):
        self.store = get_typestore(Stores.ROS2_JAZZY)
        self._cache = {}

    @staticmethod
    def _nested(fields):
        """Yield the message type names a rosbags field list uses (plain, array, sequence)."""
        for _, (nodetype, payload) in fields:
            if nodetype.name == 'NAME':
                yield payload
            elif nodetype.name in ('ARRAY', 'SEQUENCE') and payload[0][0].name == 'NAME':
                yield payload[0][1]

    def _register(self, msgtype, seen):
        if msgtype in self.store.fielddefs or msgtype in seen:
            return {}
        m = _TYPE.match(msgtype)
        if not m:
            raise DefinitionError('%s: not a message type name (pkg/msg/Type)' % msgtype)
        pkg, _, name = m.groups()
        path = os.path.join(_share_dir(pkg), 'msg', name + '.msg')
        try:
            with open(path, encoding='utf-8') as fh:
                text = fh.read()
        except OSError:
            raise DefinitionError('%s: no definition file %s' % (msgtype, path))
        try:
            types = get_types_from_msg(text, msgtype)
        except Exception as exc:  # rosbags parser errors
            raise DefinitionError('%s: cannot parse %s: %s' % (msgtype, path, exc))
        seen.add(msgtype)
        found = dict(types)
        for _, fields in types.values():
            for dep in self._nested(fields):
                found.update(self._register(dep, seen))
        return found

    def lookup(self, msgtype):
        """
        Return ``(definition text, RIHS01 hash)`` of ``msgtype`` (``pkg/msg/Type``).

        Raises
        ------
        DefinitionError
            Naming the type if no definition can be found or parsed.

        """
        if msgtype in self._cache:
            return self._cache[msgtype]
        if msgtype not in self.store.fielddefs:
            types = self._register(msgtype, set())
            try:
                self.store.register(types)
            except Exception as exc:  # conflicting definitions
                raise DefinitionError('%s: cannot register: %s' % (msgtype, exc))
        try:
            text, _ = self.store.generate_msgdef(msgtype, ros_version=2)
            digest = self.store.hash_rihs01(msgtype)
        except Exception as exc:  # an unknown nested type
            raise DefinitionError('%s: incomplete definition: %s' % (msgtype, exc))
        self._cache[msgtype] = (text, digest)
        return text, digest

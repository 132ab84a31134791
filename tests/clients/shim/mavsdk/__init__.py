"""`import mavsdk` for MAVSDK-Python's own examples, unmodified: the pinned wrapper installs as `mavsdk_grpc` (the
name `mavsdk` now belongs to the native binding, mavsdk_grpc/__init__.py), and its examples import `mavsdk`.

This package is that name: `mavsdk` and every `mavsdk.<module>` are the `mavsdk_grpc` modules themselves (one
module object under both names). One change: `System()` on the default gRPC port (none given, or
50051 named, as the MAVFTP examples do with a mavsdk_server of their own) takes the port from NAVIG8_MAVSDK_GRPC_PORT,
so examples run side by side each with its own mavsdk_server."""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import os
import sys

import mavsdk_grpc as _grpc
from mavsdk_grpc import System as _System


class _Alias(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """mavsdk.X -> mavsdk_grpc.X, the same module object."""

    def find_spec(self, fullname, path=None, target=None):  # noqa: ANN001, ANN201
        if fullname.startswith("mavsdk.") and not fullname.startswith("mavsdk_grpc"):
            return importlib.util.spec_from_loader(fullname, self)
        return None

    def create_module(self, spec):  # noqa: ANN001, ANN201
        module = importlib.import_module("mavsdk_grpc" + spec.name[len("mavsdk"):])
        sys.modules[spec.name] = module
        return module

    def exec_module(self, module) -> None:  # noqa: ANN001
        pass  # already executed under its own name


sys.meta_path.insert(0, _Alias())
DEFAULT_GRPC_PORT = 50051


class System(_System):
    def __init__(self, mavsdk_server_address=None, port=None, sysid=245, compid=190) -> None:  # noqa: ANN001
        if port is None or port == DEFAULT_GRPC_PORT:
            port = int(os.environ.get("NAVIG8_MAVSDK_GRPC_PORT", str(DEFAULT_GRPC_PORT)))
        super().__init__(mavsdk_server_address, port, sysid, compid)


def __getattr__(name: str):  # noqa: ANN202
    return getattr(_grpc, name)

"""Embree's C API for scenes that persist across frames: instancing, shared buffers, refits (ctypes).

The ``embreex`` binding (the ``fast`` extra) builds a scene from copied triangles and traverses it, one ray at a
time in compiled code (``EmbreeScene.run``), but exposes neither instances nor geometry updates, so a scene
through embreex alone is rebuilt every frame (``cosim.world.fastcast.embree_cast``). Embree's own library,
which embreex's wheel ships (``embreex.libs/libembree4*``), has both. This module calls it through ctypes to
attach geometry to the scene of an embreex ``EmbreeScene``, whose ``run`` then traverses it:

* the top-level scene and its device are embreex's (``EmbreeScene(device)``), their C handles read from the
  two objects after checking their layout (:func:`handles`: the object sizes, the device reference and the
  public ``is_committed`` field where the layout puts them; anything else raises :class:`EmbreeUnavailable`
  and the caller keeps the per-frame path);
* geometry buffers are numpy arrays shared with Embree (``rtcSetSharedGeometryBuffer``, no copy); the owner
  keeps them alive as long as the geometry (:class:`Geometry` holds them);
* prototype scenes are instanced with a float32 3 x 4 transform per frame (``rtcSetGeometryTransform``).

Embree 4.4 API, enum values from ``embree4/rtcore_common.h``, ``rtcore_geometry.h``, ``rtcore_buffer.h`` and
``rtcore_scene.h``.
"""
from __future__ import annotations

import ctypes
import functools
import glob
import os
from dataclasses import dataclass, field

import numpy as np

__all__ = ["EmbreeUnavailable", "Geometry", "api", "handles", "instance", "prototype_scene", "refit", "set_packed_transform",
           "set_transform",
           "triangles"]

# enum values of the Embree 4 API
GEOMETRY_TRIANGLE, GEOMETRY_INSTANCE = 0, 121
BUFFER_INDEX, BUFFER_VERTEX = 0, 1
FORMAT_UINT3, FORMAT_FLOAT3, FORMAT_FLOAT3X4_COLUMN_MAJOR = 0x5003, 0x9003, 0x9234
QUALITY_LOW, QUALITY_MEDIUM, QUALITY_HIGH, QUALITY_REFIT = 0, 1, 2, 3
SCENE_FLAG_ROBUST = 1 << 2
#: byte stride of a shared vertex: x, y, z and one pad float (Embree reads the last vertex as 16 bytes)
VERTEX_STRIDE = 16
#: byte stride of a triangle's three uint32 indices
INDEX_STRIDE = 12
#: sizes of embreex's extension objects (``EmbreeScene``: PyObject head, RTCScene, int is_committed + pad,
#: EmbreeDevice reference; ``EmbreeDevice``: PyObject head, RTCDevice), and the fields' byte offsets
SCENE_OBJECT_SIZE, DEVICE_OBJECT_SIZE = 40, 24
HANDLE_OFFSET, COMMITTED_OFFSET, DEVICE_REF_OFFSET = 16, 24, 32
#: a value written to ``EmbreeScene.is_committed`` to find it in the object's memory
_PROBE = 0x5A17C0DE


class EmbreeUnavailable(RuntimeError):
    """Embree's library or embreex's object layout is not what this module was written for."""


_P, _U, _S, _I = ctypes.c_void_p, ctypes.c_uint, ctypes.c_size_t, ctypes.c_int
_SIGNATURES = {
    "rtcNewScene": (_P, [_P]), "rtcReleaseScene": (None, [_P]), "rtcCommitScene": (None, [_P]),
    "rtcSetSceneFlags": (None, [_P, _I]), "rtcSetSceneBuildQuality": (None, [_P, _I]),
    "rtcNewGeometry": (_P, [_P, _I]), "rtcReleaseGeometry": (None, [_P]), "rtcCommitGeometry": (None, [_P]),
    "rtcSetSharedGeometryBuffer": (None, [_P, _I, _U, _I, _P, _S, _S, _S]),
    "rtcUpdateGeometryBuffer": (None, [_P, _I, _U]), "rtcSetGeometryBuildQuality": (None, [_P, _I]),
    "rtcAttachGeometryByID": (None, [_P, _P, _U]), "rtcSetGeometryInstancedScene": (None, [_P, _P]),
    "rtcSetGeometryTransform": (None, [_P, _U, _I, _P]), "rtcEnableGeometry": (None, [_P]),
    "rtcDisableGeometry": (None, [_P]), "rtcDetachGeometry": (None, [_P, _U]), "rtcGetDeviceError": (_I, [_P]),
}


@functools.lru_cache(maxsize=1)
def api() -> ctypes.CDLL:
    """Embree's library from embreex's wheel, the functions this module calls bound with their C signatures;
    :class:`EmbreeUnavailable` when there is none (ImportError when embreex is not installed). Called with the GIL
    held (``ctypes.PyDLL``): Embree reports an error through the callback embreex sets on its device, which runs
    Python code."""
    import embreex
    from embreex import rtcore_scene  # noqa: F401 - loads the library the wheel ships

    libs = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(embreex.__file__))), "embreex.libs")
    found = sorted(glob.glob(os.path.join(libs, "libembree4*"))) or sorted(glob.glob(os.path.join(
        os.path.dirname(os.path.abspath(embreex.__file__)), "*embree4*")))
    if not found:
        raise EmbreeUnavailable(f"no libembree4 beside embreex ({libs})")
    try:
        lib = ctypes.PyDLL(found[0])
        for name, (res, args) in _SIGNATURES.items():
            fn = getattr(lib, name)
            fn.restype, fn.argtypes = res, args
    except (OSError, AttributeError) as exc:
        raise EmbreeUnavailable(f"{found[0]}: {exc}") from exc
    return lib


def _word(obj: object, offset: int, ctype) -> int:
    return ctype.from_address(id(obj) + offset).value


def handles(scene: object, device: object) -> tuple[int, int]:
    """(RTCScene, RTCDevice) of an embreex ``EmbreeScene`` made with ``EmbreeScene(device)``.

    The layout is checked first: both objects' sizes, ``device`` referenced where the scene keeps it, and the
    public ``is_committed`` field where the layout puts it (written and read back); raises
    :class:`EmbreeUnavailable` when any check fails (another embreex build), before any handle is used."""
    if type(scene).__basicsize__ != SCENE_OBJECT_SIZE or type(device).__basicsize__ != DEVICE_OBJECT_SIZE:
        raise EmbreeUnavailable(f"embreex objects of {type(scene).__basicsize__} / {type(device).__basicsize__} "
                                f"bytes, not {SCENE_OBJECT_SIZE} / {DEVICE_OBJECT_SIZE}")
    if _word(scene, DEVICE_REF_OFFSET, ctypes.c_void_p) != id(device):
        raise EmbreeUnavailable("the EmbreeScene does not keep its device where expected")
    was = scene.is_committed
    scene.is_committed = _PROBE
    at = _word(scene, COMMITTED_OFFSET, ctypes.c_int)
    scene.is_committed = was
    if at != _PROBE:
        raise EmbreeUnavailable("EmbreeScene.is_committed is not where expected")
    rtc_scene, rtc_device = _word(scene, HANDLE_OFFSET, ctypes.c_void_p), _word(device, HANDLE_OFFSET, ctypes.c_void_p)
    if not rtc_scene or not rtc_device or api().rtcGetDeviceError(rtc_device) != 0:
        raise EmbreeUnavailable("embreex's scene or device handle is not valid")
    return rtc_scene, rtc_device


@dataclass
class Geometry:
    """An Embree geometry and the numpy buffers it shares (kept alive with it). ``handle`` is released by the
    scene it is attached to (the attach takes a reference; :func:`triangles` drops its own)."""

    handle: int
    buffers: list = field(default_factory=list)


def triangles(device: int, vertices: np.ndarray, faces: np.ndarray, quality: int = QUALITY_HIGH) -> Geometry:
    """A triangle geometry over shared buffers: ``vertices`` (V, 3) m (stored float32, padded to 16 bytes),
    ``faces`` (F, 3) indices (stored uint32). The vertex buffer (``Geometry.buffers[0]``, (V + 1, 4) float32)
    may be changed in place, then :func:`refit`."""
    lib = api()
    v = np.zeros((len(vertices) + 1, 4), np.float32)
    v[:len(vertices), :3] = vertices
    f = np.ascontiguousarray(faces, dtype=np.uint32)
    g = lib.rtcNewGeometry(device, GEOMETRY_TRIANGLE)
    lib.rtcSetSharedGeometryBuffer(g, BUFFER_VERTEX, 0, FORMAT_FLOAT3, v.ctypes.data, 0, VERTEX_STRIDE, len(vertices))
    lib.rtcSetSharedGeometryBuffer(g, BUFFER_INDEX, 0, FORMAT_UINT3, f.ctypes.data, 0, INDEX_STRIDE, len(f))
    lib.rtcSetGeometryBuildQuality(g, quality)
    lib.rtcCommitGeometry(g)
    return Geometry(g, [v, f])


def refit(geometry: Geometry) -> None:
    """Tell Embree the shared vertex buffer changed and commit the geometry."""
    lib = api()
    lib.rtcUpdateGeometryBuffer(geometry.handle, BUFFER_VERTEX, 0)
    lib.rtcCommitGeometry(geometry.handle)


def prototype_scene(device: int, geometry: Geometry, geom_id: int) -> int:
    """A robust scene holding ``geometry`` under ``geom_id`` (the id a hit reports), committed; the caller
    releases it (``api().rtcReleaseScene``) when done."""
    lib = api()
    s = lib.rtcNewScene(device)
    lib.rtcSetSceneFlags(s, SCENE_FLAG_ROBUST)
    lib.rtcSetSceneBuildQuality(s, QUALITY_HIGH)
    lib.rtcAttachGeometryByID(s, geometry.handle, geom_id)
    lib.rtcCommitScene(s)
    return s


def instance(device: int, top: int, proto: int, inst_id: int) -> Geometry:
    """An instance of scene ``proto`` attached to scene ``top`` under ``inst_id``; place it with
    :func:`set_transform`."""
    lib = api()
    g = lib.rtcNewGeometry(device, GEOMETRY_INSTANCE)
    lib.rtcSetGeometryInstancedScene(g, proto)
    lib.rtcAttachGeometryByID(top, g, inst_id)
    lib.rtcReleaseGeometry(g)                  # the scene holds it now
    return Geometry(g, [np.zeros((4, 3), np.float32)])


def set_transform(inst: Geometry, top_from_proto: np.ndarray) -> None:
    """Place an instance: ``top_from_proto`` (3, 4) or (4, 4) affine, float64 in, float32 column-major to
    Embree; the geometry is committed."""
    inst.buffers[0][...] = np.asarray(top_from_proto)[:3, :4].T
    _commit_transform(inst)


def set_packed_transform(inst: Geometry, packed: np.ndarray) -> None:
    """:func:`set_transform` of a transform already packed as Embree reads it: (4, 3) float32, the 3 x 4
    affine's columns (the linear map's three, then the translation)."""
    inst.buffers[0][...] = packed
    _commit_transform(inst)


def _commit_transform(inst: Geometry) -> None:
    lib = api()
    lib.rtcSetGeometryTransform(inst.handle, 0, FORMAT_FLOAT3X4_COLUMN_MAJOR, inst.buffers[0].ctypes.data)
    lib.rtcCommitGeometry(inst.handle)

"""A navigated track on the globe: local east-north-up positions back to WGS-84 latitude, longitude
and ellipsoidal height, the inverse of the readers' geodetic -> ENU
(:func:`imu_learn.fuse.aiding.rtklib.read_pos`, the NavSatFix topics of :mod:`.aiding.bag`), and
the files a map reads: a CSV, KML (``xml.etree``) and GeoJSON (``json``), all from the stdlib.

Both directions use the exact WGS-84 formulas of :mod:`.aiding.rtklib`; ECEF -> geodetic is
Bowring's iteration, run until the latitude moves less than 1e-15 rad (the round trip ENU ->
geodetic -> ENU is below a micrometre over tens of kilometres).

KML and GeoJSON list coordinates as longitude, latitude, height (their order). Heights are
ellipsoidal (WGS-84, as RTKLIB writes them), not above the geoid: the KML clamps the lines to
the ground (``altitudeMode clampToGround``) so a viewer does not misplace them by the geoid's
undulation (tens of metres).
"""
from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Dict, Sequence, Tuple

import numpy as np

from imu_learn.util.atomic import atomic_write_text

from .aiding.rtklib import WGS84_A, WGS84_E2, ecef_to_enu_rotation, llh_to_ecef

KML_NS = "http://www.opengis.net/kml/2.2"
LLH_HEADER = "t_s,latitude_deg,longitude_deg,height_m"


def ecef_to_llh_many(xyz: np.ndarray) -> np.ndarray:
    """ECEF (N, 3) [m] -> (N, 3) latitude [deg], longitude [deg], ellipsoidal height [m]."""
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    x, y, z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    p = np.hypot(x, y)
    lon = np.arctan2(y, x)
    lat = np.arctan2(z, p * (1.0 - WGS84_E2))
    for _ in range(30):
        n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
        h = _height(p, z, lat, n)
        new = np.arctan2(z, p * (1.0 - WGS84_E2 * n / (n + h)))
        done = np.max(np.abs(new - lat), initial=0.0) < 1e-15
        lat = new
        if done:
            break
    n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    return np.stack([np.degrees(lat), np.degrees(lon), _height(p, z, lat, n)], axis=1)


def _height(p: np.ndarray, z: np.ndarray, lat: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Ellipsoidal height, by the better-conditioned formula at each latitude."""
    low = np.abs(lat) < np.pi / 4
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(low, p / np.cos(lat) - n, z / np.sin(lat) - n * (1.0 - WGS84_E2))


def llh_to_enu(llh: np.ndarray, origin_llh: Sequence[float]) -> np.ndarray:
    """(N, 3) latitude [deg], longitude [deg], height [m] -> east, north, up [m] at ``origin_llh``
    (what the readers do)."""
    llh = np.asarray(llh, dtype=np.float64).reshape(-1, 3)
    x0 = llh_to_ecef(*origin_llh)
    R = ecef_to_enu_rotation(origin_llh[0], origin_llh[1])
    return (llh_to_ecef(llh[:, 0], llh[:, 1], llh[:, 2]) - x0) @ R.T


def enu_to_llh(enu: np.ndarray, origin_llh: Sequence[float]) -> np.ndarray:
    """East, north, up (N, 3) [m] at ``origin_llh`` -> (N, 3) latitude [deg], longitude [deg],
    ellipsoidal height [m]: the inverse of :func:`llh_to_enu`."""
    enu = np.asarray(enu, dtype=np.float64).reshape(-1, 3)
    x0 = llh_to_ecef(*origin_llh)
    R = ecef_to_enu_rotation(origin_llh[0], origin_llh[1])
    return ecef_to_llh_many(x0 + enu @ R)


# --- files -----------------------------------------------------------------------------------------

def write_llh_csv(path: Path, t_ns: np.ndarray, llh: np.ndarray) -> None:
    """``t_s,latitude_deg,longitude_deg,height_m`` a line (seconds on the run's clock; 9 decimals of a
    degree: 0.1 mm)."""
    lines = [LLH_HEADER] + [f"{int(t) // 1_000_000_000}.{int(t) % 1_000_000_000:09d},{a:.10f},{b:.10f},{h:.4f}"
                            for t, (a, b, h) in zip(np.asarray(t_ns, dtype=np.int64).tolist(), llh.tolist())]
    atomic_write_text(Path(path), "\n".join(lines) + "\n")


def write_kml(path: Path, name: str, tracks: Dict[str, np.ndarray]) -> None:
    """One Placemark with a LineString per track (``{name: llh (N, 3)}``), lon,lat,height each."""
    ET.register_namespace("", KML_NS)
    kml = ET.Element(f"{{{KML_NS}}}kml")
    doc = ET.SubElement(kml, f"{{{KML_NS}}}Document")
    ET.SubElement(doc, f"{{{KML_NS}}}name").text = name
    colors = ("ff0000ff", "ffff0000", "ff00ff00", "ff00ffff")  # aabbggrr: red, blue, green, yellow
    for i, (track, llh) in enumerate(tracks.items()):
        style = ET.SubElement(doc, f"{{{KML_NS}}}Style", id=track)
        line = ET.SubElement(style, f"{{{KML_NS}}}LineStyle")
        ET.SubElement(line, f"{{{KML_NS}}}color").text = colors[i % len(colors)]
        ET.SubElement(line, f"{{{KML_NS}}}width").text = "2"
        pm = ET.SubElement(doc, f"{{{KML_NS}}}Placemark")
        ET.SubElement(pm, f"{{{KML_NS}}}name").text = track
        ET.SubElement(pm, f"{{{KML_NS}}}styleUrl").text = f"#{track}"
        ls = ET.SubElement(pm, f"{{{KML_NS}}}LineString")
        ET.SubElement(ls, f"{{{KML_NS}}}tessellate").text = "1"
        ET.SubElement(ls, f"{{{KML_NS}}}altitudeMode").text = "clampToGround"
        ET.SubElement(ls, f"{{{KML_NS}}}coordinates").text = " ".join(
            f"{lon:.9f},{lat:.9f},{h:.3f}" for lat, lon, h in llh.tolist())
    ET.indent(kml)
    text = ET.tostring(kml, encoding="unicode", xml_declaration=False)
    atomic_write_text(Path(path), '<?xml version="1.0" encoding="UTF-8"?>\n' + text + "\n")


def write_geojson(path: Path, tracks: Dict[str, Tuple[np.ndarray, np.ndarray]]) -> None:
    """A FeatureCollection with one LineString Feature per track (``{name: (t_ns, llh (N, 3))}``):
    coordinates [lon, lat, height] (RFC 7946), the first and last stamps [s] as properties."""
    feats = []
    for track, (t_ns, llh) in tracks.items():
        coords = [[round(lon, 9), round(lat, 9), round(h, 3)] for lat, lon, h in llh.tolist()]
        feats.append({"type": "Feature", "properties": {"name": track, "t_first_s": int(t_ns[0]) * 1e-9,
                                                         "t_last_s": int(t_ns[-1]) * 1e-9, "points": len(coords)},
                      "geometry": {"type": "LineString", "coordinates": coords}})
    atomic_write_text(Path(path), json.dumps({"type": "FeatureCollection", "features": feats}) + "\n")

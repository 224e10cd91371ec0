"""Encodes huddle values as std_msgs messages with pycdr2, the reference encoder.

stdin: one JSON object per line, {"type": "int|float|bool|string|floats|bytes",
"value": ...} (floats as strings so that inf and -0.0 survive JSON);
stdout: the CDR bytes of each, in hex, one per line.
"""
import json
import sys
from dataclasses import dataclass

from pycdr2 import IdlStruct
from pycdr2.types import float64, int64, sequence, uint8, uint32


@dataclass
class Int64(IdlStruct, typename="std_msgs/msg/Int64"):
    data: int64


@dataclass
class Float64(IdlStruct, typename="std_msgs/msg/Float64"):
    data: float64


@dataclass
class Bool(IdlStruct, typename="std_msgs/msg/Bool"):
    data: bool


@dataclass
class String(IdlStruct, typename="std_msgs/msg/String"):
    data: str


@dataclass
class MultiArrayDimension(IdlStruct, typename="std_msgs/msg/MultiArrayDimension"):
    label: str
    size: uint32
    stride: uint32


@dataclass
class MultiArrayLayout(IdlStruct, typename="std_msgs/msg/MultiArrayLayout"):
    dim: sequence[MultiArrayDimension]
    data_offset: uint32


@dataclass
class Float64MultiArray(IdlStruct, typename="std_msgs/msg/Float64MultiArray"):
    layout: MultiArrayLayout
    data: sequence[float64]


@dataclass
class UInt8MultiArray(IdlStruct, typename="std_msgs/msg/UInt8MultiArray"):
    layout: MultiArrayLayout
    data: sequence[uint8]


def message(kind, value):
    empty = MultiArrayLayout(dim=[], data_offset=0)
    if kind == "int":
        return Int64(int(value))
    if kind == "float":
        return Float64(float(value))
    if kind == "bool":
        return Bool(bool(value))
    if kind == "string":
        return String(value)
    if kind == "floats":
        return Float64MultiArray(layout=empty, data=[float(x) for x in value])
    if kind == "bytes":
        return UInt8MultiArray(layout=empty, data=list(value))
    raise ValueError(kind)


for line in sys.stdin:
    if line.strip():
        item = json.loads(line)
        print(message(item["type"], item["value"]).serialize().hex())

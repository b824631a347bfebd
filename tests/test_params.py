"""``slamcli.params.build_params``: key=value parsing into frozen dataclasses with one-line ConfigErrors."""

from __future__ import annotations

import enum
from dataclasses import FrozenInstanceError, dataclass
from typing import Literal

import pytest

from slamcli.errors import ConfigError
from slamcli.params import build_params, describe_params, split_override
from slamcli.solvers.odometry import OdometryParams


class Kernel(enum.Enum):
    NONE = "none"
    HUBER = "huber"


@dataclass(frozen=True)
class P:
    flag: bool = False
    n: int = 3
    x: float = 0.5
    name: str = "a"
    mode: Literal["gn", "lm"] = "lm"
    kernel: Kernel = Kernel.NONE
    sig: tuple[float, ...] = (1.0, 2.0)
    pair: tuple[int, int] = (0, 1)
    mat: tuple[tuple[float, ...], ...] = ((1.0, 0.0), (0.0, 1.0))
    opt: float | None = None

    def __post_init__(self):
        if self.n < 0:
            raise ValueError("n must be >= 0")


def test_defaults_and_every_type():
    p = build_params(P, ["flag=yes", "n=7", "x=1e-3", "name=hello=world", "mode=gn", "kernel=huber",
                         "sig=0.1,0.2,0.3", "pair=[4, 5]", "mat=[[2,0],[0,3]]", "opt=2.5"])
    assert p == P(flag=True, n=7, x=0.001, name="hello=world", mode="gn", kernel=Kernel.HUBER,
                  sig=(0.1, 0.2, 0.3), pair=(4, 5), mat=((2.0, 0.0), (0.0, 3.0)), opt=2.5)
    assert build_params(P, []) == P()
    assert build_params(P, {"opt": "none", "kernel": "HUBER", "n": 4.0}) == P(opt=None, kernel=Kernel.HUBER, n=4)
    with pytest.raises(FrozenInstanceError):
        p.n = 1  # type: ignore[misc]


@pytest.mark.parametrize("text,fragment", [
    ("bogus=1", "unknown parameter 'bogus' for P; known: flag, kernel, mat, mode, n, name, opt, pair, sig, x"),
    ("flag=2", "--param flag: expected a boolean"),
    ("n=1.5", "--param n: expected an integer"),
    ("n=true", "--param n: expected an integer"),
    ("x=abc", "--param x: expected a number"),
    ("x=nan", "NaN is not allowed"),
    ("mode=newton", "'newton' is not one of gn, lm"),
    ("kernel=cauchy", "is not one of none, huber"),
    ("pair=1,2,3", "expected 2 values, got 3"),
    ("mat=[[1,2]", "cannot parse"),
    ("opt=x", "expected a number"),
    ("n=-1", "n must be >= 0"),
    ("noequals", "expected key=value"),
    ("=3", "empty key"),
])
def test_errors_are_one_line_and_specific(text, fragment):
    with pytest.raises(ConfigError) as info:
        build_params(P, [text])
    msg = str(info.value)
    assert fragment in msg and "\n" not in msg


def test_where_label_is_used():
    with pytest.raises(ConfigError, match=r"^--set: unknown parameter"):
        build_params(P, ["q=1"], where="--set")


def test_split_override():
    assert split_override(" a.b = 3 ") == ("a.b", "3")


def test_odometry_params_through_build_params():
    p = build_params(OdometryParams, ["nn_threshold=0.25", "use_reported_ids=false", "min_support=2"])
    assert p == OdometryParams(use_reported_ids=False, nn_threshold=0.25, min_support=2)
    with pytest.raises(ConfigError, match="nn_threshold must be > 0"):
        build_params(OdometryParams, ["nn_threshold=0"])


def test_describe_params():
    rows = {n: (t, d) for n, t, d in describe_params(OdometryParams)}
    assert rows == {"use_reported_ids": ("bool", "True"), "nn_threshold": ("float", "1.0"),
                    "min_support": ("int", "1")}
    assert {n: d for n, _t, d in describe_params(P)}["kernel"] == "none"

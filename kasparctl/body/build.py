"""The body the configuration asks for: a live body over these servos and voice, or a still one."""

from __future__ import annotations

import random
from collections.abc import Callable
from typing import Any, cast

import structlog

from hal.clock import Clock, LoopClock
from kasparctl.body.api import Body, StillBody
from kasparctl.body.behaviours import load_library
from kasparctl.body.engine import LiveBody, StreamingServos
from kasparctl.body.mouth import player_latency
from kasparctl.config import Config

log = structlog.get_logger("kasparctl.body")


def make_body(
    config: Config,
    servos: object,
    voice: object | None = None,
    clock: Clock | None = None,
    *,
    rng: random.Random | None = None,
) -> Body:
    """Kaspar's body: a LiveBody when `[body] enabled`, else a StillBody.

    `servos` is the joints layer (hal.servos.joints.Joints or the simulated twin);
    `voice`, when it can be listened to (hal.voice.speaker.Voice.listen), moves the
    mouth with every line. The clock is the servos' unless given. Raises
    kasparctl.body.behaviours.BehaviourError for a bad behaviour file: better at
    start than in front of the children.
    """
    settings = config.body
    if not settings.enabled:
        return StillBody()
    if not callable(getattr(servos, "stream", None)):
        log.warning("body language off: these servos cannot stream goals")
        return StillBody()
    library = load_library(settings.behaviours_dir)
    latency = settings.latency_s
    if latency is None:
        latency = player_latency(cast(str | None, getattr(voice, "player", None)))
    body = LiveBody(
        cast(StreamingServos, servos),
        settings,
        config.servos,
        library,
        clock or cast(Clock, getattr(servos, "clock", None) or LoopClock()),
        latency_s=latency,
        rng=rng,
    )
    listen = cast(Callable[[Any], bool] | None, getattr(voice, "listen", None))
    if listen is not None and not listen(body.mouth):
        log.info("the mouth does not follow this voice's sink")
    return body

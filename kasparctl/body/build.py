"""The body the configuration asks for: a live body over these servos and voice, or a still one."""

from __future__ import annotations

import random

import structlog

from hal.clock import Clock
from hal.servos.api import ServoApi
from hal.voice.api import VoiceOutput
from kasparctl.body.api import Body, StillBody
from kasparctl.body.behaviours import load_library
from kasparctl.body.engine import LiveBody
from kasparctl.body.mouth import player_latency
from kasparctl.config import Config

log = structlog.get_logger("kasparctl.body")


def make_body(
    config: Config,
    servos: ServoApi,
    voice: VoiceOutput | None = None,
    clock: Clock | None = None,
    *,
    rng: random.Random | None = None,
) -> Body:
    """Kaspar's body: a LiveBody when `[body] enabled`, else a StillBody.

    `servos` is the joints layer (hal.servos.joints.Joints or the simulated twin), whose
    stream steps the body sends; `voice`, when its output can be listened to
    (VoiceOutput.listen), moves the mouth with every line. The clock is the servos'
    unless given. Raises kasparctl.body.behaviours.BehaviourError for a bad behaviour
    file: better at start than in front of the children.
    """
    settings = config.body
    if not settings.enabled:
        return StillBody()
    library = load_library(settings.behaviours_dir)
    latency = settings.latency_s
    if latency is None:
        latency = player_latency(voice.player if voice is not None else None)
    body = LiveBody(
        servos,
        settings,
        config.servos,
        library,
        clock or servos.clock,
        latency_s=latency,
        rng=rng,
    )
    if voice is not None and not voice.listen(body.mouth):
        log.info("the mouth does not follow this voice's sink")
    return body

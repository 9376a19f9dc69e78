"""Offline speech synthesis of feedback text (espeak-ng)."""

from __future__ import annotations

import asyncio

from fastapi import APIRouter, HTTPException, Response

from app.api.errors import error_responses
from app.api.schemas import SpeechRequest
from app.feedback.speech import SpeechUnavailable, synthesize_wav

router = APIRouter(tags=["speech"])


@router.post(
    "/speech",
    response_class=Response,
    responses={
        200: {"content": {"audio/wav": {}}, "description": "the spoken text, a WAV file"},
        **error_responses(400, 413, 422, 503),
    },
    summary="Speak text as a WAV file",
)
async def speech(body: SpeechRequest) -> Response:
    try:
        wav = await asyncio.to_thread(synthesize_wav, body.text)
    except SpeechUnavailable as exc:
        raise HTTPException(status_code=503, detail=str(exc)) from None
    return Response(wav, media_type="audio/wav")

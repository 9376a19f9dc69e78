"""Spoken-style feedback: clock directions, distances as people say them, no repetition."""

from app.feedback.narrator import Feedback, FeedbackItem, FeedbackOptions, Narrator
from app.feedback.phrasing import clock_from_bearing_deg, direction_phrase, distance_phrase

__all__ = [
    "Feedback",
    "FeedbackItem",
    "FeedbackOptions",
    "Narrator",
    "clock_from_bearing_deg",
    "direction_phrase",
    "distance_phrase",
]

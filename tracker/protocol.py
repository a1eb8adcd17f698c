"""The contract every tracker meets, built in or brought by a user: how it is made and how it is fed.

A tracker is a class constructed as ``Tracker(cameras, config, skeleton)`` and fed one camera frame at a time,
in delivery order, through ``update(frame) -> targets``:

```python
tracker = MyTracker(cameras, config, skeleton)  # Sequence[Camera], TrackerConfig, Skeleton
for frame in frames:                            # core.types.Frame: one camera, one stamp
    targets = tracker.update(frame)             # Sequence[tracker.types.Target], poses at frame.stamp_s
```

What each target must hold (the command line checks it after every frame, see crossview/plugins.py):
- ``id``: an int (Python or numpy integer, not a bool), unique within one output, the same person's id
  from frame to frame;
- ``pose``: a (J, 3) array of world points in metres, J = ``skeleton.num_joints``; a joint the tracker does not
  know is NaN in all three coordinates; no infinite values, and at least one finite joint;
- ``stamp_s`` (optional): the time the pose refers to; the frame's stamp when absent;
- ``state`` (optional): a `TargetState`; CONFIRMED when absent.

A tracker may also keep ``last_output``, the `TrackerOutput` of its latest update, whose
``detection_target_ids`` say which target each of the frame's detections went to; with it the score includes
the association accuracy, without it that metric is left out (null). Built-in trackers keep it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, runtime_checkable

from core.types import Camera, Frame, Skeleton
from tracker.config import TrackerConfig
from tracker.types import Target


@runtime_checkable
class PoseTracker(Protocol):
    """A stateful tracker: one `update` per camera frame, in delivery order."""

    def update(self, frame: Frame) -> Sequence[Target]:
        """Processes one camera frame and returns the targets it reports at `frame.stamp_s`.

        Args:
            frame: detections of one camera, distorted pixels (D, J, 2), scores (D, J).

        Returns:
            targets with an int `id` and a (J, 3) `pose` in metres (NaN for an unknown joint).
        """
        ...


class PoseTrackerClass(Protocol):
    """What `--method package.module:Class` names: a class (or any callable) that makes a `PoseTracker`."""

    def __call__(self, cameras: Sequence[Camera], config: TrackerConfig, skeleton: Skeleton) -> PoseTracker:
        ...

//! The edge's `[ros2_out]` session: opened in the background while the robot maps, closed
//! when the run ends.

use crate::ros_out::TfOut;
use runtime::ros2::RosOutConfig;
use std::time::Duration;
use tokio::sync::oneshot;

/// With `[ros2_out]`, how long an edge whose source ended and whose nodes are all acked waits
/// for the mapper's pose of its last node, so that its last transform is of the final map.
pub(super) const FINAL_CORRECTION_WAIT: Duration = Duration::from_secs(3);

/// How long to wait before trying `[ros2_out]`'s session again.
const TF_OUT_RETRY: Duration = Duration::from_secs(5);

/// Opens `[ros2_out]` in the background, again every [`TF_OUT_RETRY`] while the robot's ROS 2
/// network is out of reach (the robot maps meanwhile; only the transform waits).
pub(super) fn open_tf_out(config: RosOutConfig) -> oneshot::Receiver<TfOut> {
    let (tx, rx) = oneshot::channel();
    tokio::spawn(async move {
        loop {
            match TfOut::open(&config).await {
                Ok(tf_out) => {
                    let _ = tx.send(tf_out);
                    return;
                }
                Err(e) => tracing::warn!("[ros2_out] not open ({e:#}); retrying"),
            }
            tokio::time::sleep(TF_OUT_RETRY).await;
        }
    });
    rx
}

/// Closes `[ros2_out]`'s session, so that the last transforms go out before the run ends;
/// a dead network gets `bound`.
pub(super) async fn close_tf_out(tf_out: TfOut, bound: Duration) {
    match tokio::time::timeout(bound, tf_out.close()).await {
        Ok(Err(e)) => tracing::warn!("[ros2_out] close: {e:#}"),
        Err(_) => tracing::warn!("[ros2_out] close took over {bound:?}"),
        Ok(Ok(())) => {}
    }
}

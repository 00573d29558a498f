//! The UDP body controller against the simulated lower computer, in process,
//! over loopback: the behaviour of `hexapod-udp.md` end to end.

use std::net::SocketAddr;
use std::time::Duration;

use groundcal_calib::geometry::PoseDegMm;
use groundcal_hal::sim::lower_computer::{FaultInjection, SimOptions, SimServer, SimStats};
use groundcal_hal::udp::client::Request;
use groundcal_hal::udp::proto::{self, AckStatus, Datagram, Message};
use groundcal_hal::udp::{LinkConfig, UdpBodyController};
use groundcal_hal::{BodyController, Error, ErrorKind, MotionState};
use tokio::sync::oneshot;
use tokio::task::JoinHandle;

/// A simulated lower computer on a loopback port, until `stop` is called.
struct Sim {
    address: SocketAddr,
    stop: oneshot::Sender<()>,
    task: JoinHandle<std::io::Result<SimStats>>,
}

impl Sim {
    async fn start(time_scale: f64, faults: FaultInjection) -> Self {
        let options = SimOptions {
            faults,
            ..SimOptions::new(11, time_scale)
        };
        let server = SimServer::bind("127.0.0.1:0".parse().unwrap(), options)
            .await
            .unwrap();
        let address = server.local_addr();
        let (stop, stopped) = oneshot::channel();
        let task = tokio::spawn(server.run(async {
            let _ = stopped.await;
        }));
        Self {
            address,
            stop,
            task,
        }
    }

    async fn stop(self) -> SimStats {
        let _ = self.stop.send(());
        self.task.await.unwrap().unwrap()
    }
}

fn pose(beta_deg: f64, gamma_deg: f64, py_mm: f64) -> PoseDegMm {
    PoseDegMm {
        alpha_deg: 0.0,
        beta_deg,
        gamma_deg,
        px_mm: 0.0,
        py_mm,
        pz_mm: 0.0,
    }
}

/// Twelve poses like the sample recording's.
fn poses() -> Vec<PoseDegMm> {
    (0..12)
        .map(|k| {
            let s = if k % 2 == 0 { 1.0 } else { -1.0 };
            pose(
                s * (2.0 + k as f64),
                s * (18.0 - k as f64),
                610.0 + 8.0 * k as f64,
            )
        })
        .collect()
}

async fn visit(controller: &mut UdpBodyController, poses: &[PoseDegMm]) {
    for (k, p) in poses.iter().enumerate() {
        let id = (k + 1) as u16;
        controller.set_pose(id, p, 1000).await.unwrap();
        let state = controller
            .wait_while_moving(Duration::from_millis(10), Duration::from_secs(5))
            .await
            .unwrap();
        assert_eq!((state.state, state.pose_id), (MotionState::Settled, id));
    }
}

#[tokio::test]
async fn a_session_on_a_perfect_network() {
    let sim = Sim::start(100.0, FaultInjection::default()).await;
    let mut c = UdpBodyController::connect(&LinkConfig::new(sim.address))
        .await
        .unwrap();
    let welcome = c.hello().await.unwrap();
    assert_eq!(welcome.limits.max_tilt_deg, 25.0);
    assert_eq!(welcome.limits.min_height_mm, 500.0);
    assert_eq!(welcome.firmware, "groundcal-sim 1");
    let home = c.state().await.unwrap();
    assert_eq!(home.state, MotionState::Idle);
    for foot in home.feet_mm {
        assert!((foot[1] + 600.0).abs() < 20.0, "{foot:?}");
    }
    visit(&mut c, &poses()[..3]).await;
    // Outside the limits: refused with ACK 1, the body stays.
    let e = c
        .set_pose(9, &pose(0.0, 30.0, 600.0), 1000)
        .await
        .unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Refused);
    assert!(e.to_string().contains("ACK 1"), "{e}");
    assert_eq!(c.state().await.unwrap().pose_id, 3);
    c.halt().await.unwrap();
    assert_eq!(c.state().await.unwrap().state, MotionState::Halted);
    c.home(1000).await.unwrap();
    let idle = c
        .wait_while_moving(Duration::from_millis(10), Duration::from_secs(5))
        .await
        .unwrap();
    assert_eq!((idle.state, idle.pose_id), (MotionState::Idle, 0));
    c.bye().await.unwrap();
    assert_eq!(c.link().stats().retransmissions, 0);
    let stats = sim.stop().await;
    assert_eq!(stats.watchdog_halts(), 0);
    assert_eq!(stats.lives[0].retransmissions, 0);
}

#[tokio::test]
async fn a_lossy_network_and_a_restart_are_recovered() {
    let faults = FaultInjection::parse(
        "loss=0.2,dup=0.05,reorder=0.05,delay_ms=20,restart_after_pose=6,seed=5",
    )
    .unwrap();
    let sim = Sim::start(100.0, faults).await;
    // 30 retries: at 20 % loss each way the default 10 would lose the link
    // now and then (p = 0.36 per attempt).
    let mut link = LinkConfig::new(sim.address);
    link.client.retry_limit = 30;
    let mut c = UdpBodyController::connect(&link).await.unwrap();
    c.hello().await.unwrap();
    visit(&mut c, &poses()).await;
    let client = c.link().stats();
    drop(c);
    let stats = sim.stop().await;
    assert_eq!(stats.restarts, 1);
    assert_eq!(client.renewals, 1, "{client:?}");
    assert!(client.retransmissions > 0);
    assert_eq!(stats.watchdog_halts(), 0);
    assert!(stats.faults.lost_in > 0 && stats.faults.lost_out > 0);
}

/// The link keeps the watchdog fed while the caller does something else.
#[tokio::test]
async fn keepalives_feed_the_watchdog_while_the_caller_is_busy() {
    let sim = Sim::start(1.0, FaultInjection::default()).await;
    let mut c = UdpBodyController::connect(&LinkConfig::new(sim.address))
        .await
        .unwrap();
    c.set_pose(1, &pose(5.0, 5.0, 650.0), 2500).await.unwrap();
    // Busy for longer than the watchdog's second.
    tokio::time::sleep(Duration::from_millis(1600)).await;
    let latest = c.latest_state().expect("keep-alives report the state");
    assert_eq!(latest.state, MotionState::Moving);
    let state = c
        .wait_while_moving(Duration::from_millis(50), Duration::from_secs(5))
        .await
        .unwrap();
    assert_eq!((state.state, state.pose_id), (MotionState::Settled, 1));
    let keepalives = c.link().stats().keepalives;
    assert!(keepalives >= 8, "{keepalives} keep-alives in 1.6 s");
    drop(c);
    let stats = sim.stop().await;
    assert_eq!(stats.watchdog_halts(), 0);
}

/// An upper computer that falls silent mid-motion: the body halts after 1 s.
#[tokio::test]
async fn the_watchdog_halts_when_the_upper_computer_falls_silent() {
    let sim = Sim::start(1.0, FaultInjection::default()).await;
    let socket = tokio::net::UdpSocket::bind("127.0.0.1:0").await.unwrap();
    let exchange = |seq: u32, session: u32, message: Message| {
        let bytes = proto::encode(&Datagram {
            session,
            seq,
            message,
        });
        let socket = &socket;
        let address = sim.address;
        async move {
            socket.send_to(&bytes, address).await.unwrap();
            let mut buffer = [0u8; 256];
            let (n, _) = socket.recv_from(&mut buffer).await.unwrap();
            proto::decode(&buffer[..n]).unwrap()
        }
    };
    let welcome = exchange(1, 0, Message::Hello { nonce: 9 }).await;
    let session = welcome.session;
    let set = Message::SetPose(proto::SetPose {
        pose_id: 1,
        alpha_deg: 0.0,
        beta_deg: 10.0,
        gamma_deg: 0.0,
        px_mm: 0.0,
        py_mm: 650.0,
        pz_mm: 0.0,
        duration_ms: 5000,
    });
    let ack = exchange(2, session, set).await;
    assert_eq!(ack.message, Message::Ack(AckStatus::Accepted));
    tokio::time::sleep(Duration::from_millis(1300)).await;
    let state = exchange(3, session, Message::GetState).await;
    match state.message {
        Message::State(s) => assert_eq!(s.state, MotionState::Halted),
        other => panic!("{other:?}"),
    }
    let stats = sim.stop().await;
    assert_eq!(stats.watchdog_halts(), 1);
}

/// The raw client request API is usable without the controller too.
#[tokio::test]
async fn the_link_answers_raw_requests() {
    let sim = Sim::start(100.0, FaultInjection::default()).await;
    let link = groundcal_hal::udp::link::Link::open(&LinkConfig::new(sim.address))
        .await
        .unwrap();
    let reply = link.request(Request::GetState).await.unwrap();
    assert!(matches!(
        reply,
        groundcal_hal::udp::client::Reply::State(s) if s.state == MotionState::Idle
    ));
    drop(link);
    sim.stop().await;
}

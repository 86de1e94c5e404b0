//! Typed requests: every [`Request`] has a struct of the same name here, paired with the
//! type of its reply, so a host call such as `link.call(GetStatus)` returns a [`Status`]
//! and asking the wrong question is a compile error, not a runtime surprise. The wire
//! format is unchanged: each struct converts into its [`Request`] variant, and
//! [`Endpoint::reply`] takes the [`Reply`] of the Ack apart.

use crate::messages::{ChannelSet, DeviceInfo, FaultFlags, PidGains, Reply, Request, Status};

/// A request and the reply it gets.
pub trait Endpoint: Into<Request> {
    /// What the Ack carries back.
    type Reply;
    /// The request's name (for messages and logs).
    const NAME: &'static str;
    /// The typed reply, or the reply itself back if the device answered another kind.
    fn reply(reply: Reply) -> Result<Self::Reply, Reply>;
}

/// The answer to [`Ping`]: the host's time echoed and the device time at reception.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Pong {
    pub host_time_us: u64,
    pub device_time_us: u64,
}

macro_rules! endpoint {
    // a request with named fields
    ($(#[$doc:meta])* $name:ident { $($field:ident : $ty:ty),* $(,)? } => $reply:ty, $take:expr) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq)]
        pub struct $name { $(pub $field: $ty),* }
        impl From<$name> for Request {
            fn from(r: $name) -> Request {
                let $name { $($field),* } = r;
                Request::$name { $($field),* }
            }
        }
        impl Endpoint for $name {
            type Reply = $reply;
            const NAME: &'static str = stringify!($name);
            fn reply(reply: Reply) -> Result<$reply, Reply> {
                $take(reply)
            }
        }
    };
    // a request without fields
    ($(#[$doc:meta])* $name:ident => $reply:ty, $take:expr) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        pub struct $name;
        impl From<$name> for Request {
            fn from(_: $name) -> Request {
                Request::$name
            }
        }
        impl Endpoint for $name {
            type Reply = $reply;
            const NAME: &'static str = stringify!($name);
            fn reply(reply: Reply) -> Result<$reply, Reply> {
                $take(reply)
            }
        }
    };
}

/// An Ack with nothing beyond the acknowledgement.
fn done(reply: Reply) -> Result<(), Reply> {
    match reply {
        Reply::Done => Ok(()),
        other => Err(other),
    }
}

endpoint!(
    /// Handshake.
    Hello { host_protocol_version: u8 } => DeviceInfo,
    |r| match r { Reply::Info(i) => Ok(i), other => Err(other) });
endpoint!(
/// Clock-mapping round trip (also a heartbeat).
Ping { host_time_us: u64 } => Pong,
|r| match r {
    Reply::Pong { host_time_us, device_time_us } => Ok(Pong { host_time_us, device_time_us }),
    other => Err(other),
});
endpoint!(
    /// Keep-alive.
    Heartbeat => (), done);
endpoint!(
    /// Regulate the gauge pressure to this setpoint.
    SetPressure { setpoint_kpa: f32 } => (), done);
endpoint!(
    /// Pump off, regulation stopped.
    PressureOff => (), done);
endpoint!(
    /// Open-loop pump duty (1/10000 of full scale).
    PumpManual { duty_per_10k: u16 } => (), done);
endpoint!(
    /// Open or close the vent valve.
    Vent { open: bool } => (), done);
endpoint!(
    /// Start streaming samples.
    StartStream { rate_hz: u16, channels: ChannelSet } => (), done);
endpoint!(
    /// Stop streaming samples.
    StopStream => (), done);
endpoint!(
    /// Take the current load-cell reading as zero.
    TareLoad => (), done);
endpoint!(
    /// Move the stage with a trapezoidal profile.
    MoveStage { target_steps: i32, speed_steps_per_s: u32, accel_steps_per_s2: u32 } => (), done);
endpoint!(
    /// Decelerate the stage to a stop.
    StopStage => (), done);
endpoint!(
    /// The stage's soft limits.
    SetStageLimits { min_steps: i32, max_steps: i32 } => (), done);
endpoint!(
    /// Declare the current stage position (homing).
    SetStagePosition { position_steps: i32 } => (), done);
endpoint!(
    /// Clear the latched faults whose cause is gone; the reply is those still latched.
    ClearFault => FaultFlags,
    |r| match r { Reply::FaultsRemaining(f) => Ok(f), other => Err(other) });
endpoint!(
    /// The controller's state.
    GetStatus => Status,
    |r| match r { Reply::Status(s) => Ok(s), other => Err(other) });
endpoint!(
    /// LED brightness (1/10000 of full scale).
    SetLed { duty_per_10k: u16 } => (), done);
endpoint!(
    /// Reboot into the boot ROM for flashing.
    EnterBootloader => (), done);

/// Replace the pressure PID gains.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SetPidGains(pub PidGains);

impl From<SetPidGains> for Request {
    fn from(r: SetPidGains) -> Request {
        Request::SetPidGains(r.0)
    }
}

impl Endpoint for SetPidGains {
    type Reply = ();
    const NAME: &'static str = "SetPidGains";
    fn reply(reply: Reply) -> Result<(), Reply> {
        done(reply)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn typed_requests_are_the_wire_variants() {
        assert_eq!(
            Request::from(SetPressure { setpoint_kpa: 6.0 }),
            Request::SetPressure { setpoint_kpa: 6.0 }
        );
        assert_eq!(Request::from(GetStatus), Request::GetStatus);
        assert_eq!(
            Request::from(MoveStage {
                target_steps: -5,
                speed_steps_per_s: 100,
                accel_steps_per_s2: 1000
            }),
            Request::MoveStage {
                target_steps: -5,
                speed_steps_per_s: 100,
                accel_steps_per_s2: 1000
            }
        );
        assert_eq!(<GetStatus as Endpoint>::NAME, "GetStatus");
    }

    #[test]
    fn a_reply_of_the_wrong_kind_is_handed_back() {
        assert_eq!(<Heartbeat as Endpoint>::reply(Reply::Done), Ok(()));
        assert_eq!(
            <ClearFault as Endpoint>::reply(Reply::FaultsRemaining(FaultFlags(0))),
            Ok(FaultFlags(0))
        );
        assert_eq!(
            <GetStatus as Endpoint>::reply(Reply::Done),
            Err(Reply::Done)
        );
        assert_eq!(
            <Ping as Endpoint>::reply(Reply::Pong {
                host_time_us: 1,
                device_time_us: 2
            }),
            Ok(Pong {
                host_time_us: 1,
                device_time_us: 2
            })
        );
    }
}

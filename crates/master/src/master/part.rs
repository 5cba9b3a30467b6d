//! The master's parts, as an application reaches them: each borrows the master for as long as
//! it is used and offers one concern's operations ([`Master::config`],
//! [`Master::states`], [`Master::cyclic`], [`Master::dc`], [`Master::clock`],
//! [`Master::acyclic`], [`Master::diagnosis`]). A part is cheap to take: take it again for the
//! next call (`m.cyclic().cycle()?`), or hold it for several (`let mut c = m.cyclic();`).
//! Accessors that give a reference consume the part, so that the reference lives as long as
//! the borrow of the master.
use super::Master;
use crate::io::Io;

macro_rules! part {
    ($(#[$doc:meta])* $name:ident, $accessor:ident) => {
        $(#[$doc])*
        pub struct $name<'a, I: Io> {
            pub(crate) m: &'a mut Master<I>,
        }

        impl<I: Io> Master<I> {
            $(#[$doc])*
            pub fn $accessor(&mut self) -> $name<'_, I> {
                $name { m: self }
            }
        }
    };
}

part!(
    /// The configuration: settings, ESI descriptions, plans and groups, the application's set-up
    /// of each slave (modules, init commands, PDO choice, watchdog).
    Config, config
);
part!(
    /// The AL states: the scan and bring-up, state requests, bootstrap, supervision in OP.
    States, states
);
part!(
    /// The cyclic core: the link and its frames, the cycle, the outputs, the master's time and
    /// sleep.
    Cyclic, cyclic
);
part!(
    /// Distributed clocks: initialisation, monitoring, the reference clock and the ring's
    /// delays.
    Dc, dc
);
part!(
    /// The master's clock and its clock-sync method: system time, the method's start, steps
    /// and state.
    Clock, clock
);
part!(
    /// The acyclic side: the mailbox clients (CoE, EoE, FoE), the slaves' EEPROMs, and the
    /// requests of other processes, served in the cycle's spare time.
    Acyclic, acyclic
);
part!(
    /// Diagnosis: the events, the error counters, the cyclic exchange's statistics.
    Diagnosis, diagnosis
);

/// The process image, to read: its bytes, the variables' values and handles, its sizes and
/// the working counter a whole cycle gives. It borrows the master shared, so that code holding
/// only `&Master` reads the inputs (`m.image().get(h)`).
#[derive(Clone, Copy)]
pub struct Image<'a, I: Io> {
    pub(crate) m: &'a Master<I>,
}

impl<I: Io> Master<I> {
    /// The process image, to read ([`Image`]); the cyclic core ([`Master::cyclic`]) writes it.
    pub fn image(&self) -> Image<'_, I> {
        Image { m: self }
    }
}

//! An interactive viewer (DESIGN §12): a small server that steps one simulation of a mesh in real
//! time and serves a page (hand-written WebGL2, compiled into the binary) on which a person
//! drags the mesh with the mouse, as in AutoDef.
//!
//! A [`Session`] holds named [`Method`]s (any [`latent_sim::Interactive`] simulator: a trained
//! model's [`latent_sim::ReducedRuntime`], the [`latent_sim::FullRuntime`] for contrast) over
//! one mesh; [`Server::bind`] listens, steps the session on its own thread and streams surface
//! positions to every connected page. The messages ([`protocol`]) are documented in
//! `docs/viewer.md`, so a script or a test can drive a session without the page.
//!
//! ```no_run
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! use latent_sim::{FullRuntime, ReducedModel};
//! use viewer::{Method, Server, Session, Settings};
//!
//! let model = ReducedModel::load("out/cantilever/neural-cubature.ldm")?;
//! let methods = vec![
//!     Method::new("neural-cubature", model.simulator()?),
//!     Method::new("full", FullRuntime::from_model(&model)?),
//! ];
//! let session = Session::new(Settings::for_model(&model), methods)?;
//! let server = Server::bind("127.0.0.1:0", session)?;
//! println!("open {}", server.url());
//! server.wait();
//! # Ok(())
//! # }
//! ```

mod http;
pub mod protocol;
mod server;
mod session;
mod simulator;

pub use server::Server;
pub use session::Session;
pub use simulator::{Method, Settings};

/// Errors of setting up a session or a server (nothing a client sends is one: clients get
/// error replies).
#[derive(Debug, thiserror::Error)]
pub enum ViewerError {
    /// A session with no method to step.
    #[error("a viewer session needs at least one method")]
    NoMethods,
    /// Two methods under one name.
    #[error("two methods are named {0:?}")]
    DuplicateMethod(String),
    /// Methods over different meshes.
    #[error("methods {first:?} and {other:?} simulate different meshes (surface or vertices)")]
    SurfaceMismatch { first: String, other: String },
    /// A pinned vertex past the mesh's vertices.
    #[error("pinned vertex {vertex} does not exist (the mesh has {count})")]
    PinnedVertex { vertex: usize, count: usize },
    /// A setting that must be positive and finite (and, for a time, at most a year).
    #[error("the viewer's {what} must be positive and finite (a year at most), got {value}")]
    Setting { what: &'static str, value: f64 },
    /// The direction drawn up is not a unit vector.
    #[error("the viewer's up must be a unit vector, got one of length {length}")]
    Up { length: f64 },
    /// The address cannot be listened on.
    #[error("cannot listen on {addr}: {source}")]
    Bind {
        addr: String,
        source: std::io::Error,
    },
    /// A server thread cannot start.
    #[error("cannot start a viewer thread: {0}")]
    Thread(std::io::Error),
}

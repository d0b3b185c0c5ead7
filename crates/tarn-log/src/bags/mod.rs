//! Robot logs beyond MCAP (feature `bags`): rosbag2's sqlite3 storage ([`Db3Reader`]) and
//! ROS 1 bags ([`Ros1Reader`]). Both are [`crate::log::MessageSource`]s; open any log
//! with [`crate::log::open`].

mod db3;
mod ros1;

pub use db3::Db3Reader;
pub use ros1::Ros1Reader;

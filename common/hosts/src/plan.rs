//! Which member runs where, decided once before the team's services exist.

use std::collections::BTreeSet;
use std::sync::Arc;

use cdm_iox::{TeamLayout, TeamName};
use cdm_scenario::Scenario;
use cdm_team::notices::NoticeSink;

use crate::error::{BridgeError, PlanError};
use crate::notice::HostNotice;
use crate::other_hosts::{OneHost, OtherHosts};
use crate::placed::placed;
use crate::regions::{Placed, Regions};
use crate::{HostOptions, TeamFlight, Transport};

/// The split of a team over its hosts (host 0 is this one).
pub struct HostPlan {
    regions: Regions,
    placed: Vec<Placed>,
    options: HostOptions,
    /// Where the split and, later, the bridge's notices go.
    #[cfg_attr(not(feature = "hosts"), allow(dead_code))]
    notices: Arc<dyn NoticeSink>,
}

impl HostPlan {
    /// Splits the team and says which ids went where (one line per host).
    pub fn new(
        s: &Scenario,
        h: &HostOptions,
        team: &TeamName,
        notices: Arc<dyn NoticeSink>,
    ) -> Result<Self, PlanError> {
        let members = s.formation.members.len();
        if h.hosts as usize > members {
            return Err(PlanError::TooManyHosts {
                hosts: h.hosts,
                members,
            });
        }
        if h.hosts > 1 && !cfg!(feature = "hosts") {
            return Err(PlanError::NotBuilt);
        }
        if h.hosts > 1 && h.listen.is_none() {
            return Err(PlanError::NoListen);
        }
        let placed = placed(s);
        let regions = Regions::split(&placed, h.hosts);
        let plan = Self {
            regions,
            placed,
            options: h.clone(),
            notices,
        };
        if h.hosts > 1 {
            plan.notices.notice(&HostNotice::Split {
                team: team.to_string(),
                hosts: (0..h.hosts).map(|k| plan.regions.members(k)).collect(),
                crossing: plan.crossing().len(),
                edges: plan.placed.iter().map(|p| p.in_neighbors.len()).sum(),
                listen: h.listen.clone().unwrap_or_default(),
                how: match &h.transport {
                    Transport::Tls(_) => "--keys DIR/host-K",
                    Transport::Insecure => "--insecure",
                },
            });
        }
        Ok(plan)
    }

    /// Edges `(source, reader)` whose ends run on different hosts.
    pub fn crossing(&self) -> Vec<(u32, u32)> {
        self.regions.crossing(&self.placed)
    }

    /// The layout of this host: edges inside another host never touch its shared memory.
    pub fn hide_remote_edges(&self, layout: TeamLayout) -> TeamLayout {
        let r = &self.regions;
        let hidden: BTreeSet<(u32, u32)> = self
            .placed
            .iter()
            .flat_map(|p| p.in_neighbors.iter().map(move |&j| (j, p.id)))
            .filter(|&(j, i)| r.host_of(j) == r.host_of(i) && r.host_of(i) != 0)
            .collect();
        layout.with_hidden_edges(hidden)
    }

    /// The members of each other host (lost together if its daemon is killed).
    pub fn remote_groups(&self) -> Vec<Vec<u32>> {
        (1..self.regions.hosts())
            .map(|k| self.regions.members(k))
            .collect()
    }

    /// True when member `id` runs on this host.
    pub fn runs_here(&self, id: u32) -> bool {
        self.regions.host_of(id) == 0
    }

    /// The team's other hosts: [`OneHost`] when it has none, else the bridge, listening for
    /// their daemons.
    pub fn start_bridge(
        &self,
        s: &Scenario,
        team: &TeamName,
        flight: TeamFlight,
    ) -> Result<Box<dyn OtherHosts>, BridgeError> {
        match self.options.listen.as_deref() {
            Some(endpoint) if self.options.hosts > 1 => self.listen(endpoint, s, team, flight),
            _ => Ok(Box::new(OneHost)),
        }
    }

    #[cfg(feature = "hosts")]
    fn listen(
        &self,
        endpoint: &str,
        s: &Scenario,
        team: &TeamName,
        flight: TeamFlight,
    ) -> Result<Box<dyn OtherHosts>, BridgeError> {
        let security = crate::security::listener(&self.options)?;
        if let Some(w) = self.options.transport.warning(endpoint) {
            tracing::warn!("{w}");
        }
        let net = cdm_zenoh::Net::listen(endpoint, &security).map_err(BridgeError::Endpoint)?;
        let (regions, h) = (&self.regions, &self.options);
        let bridge =
            crate::bridge::Bridge::start(net, s, team, regions, h, flight, self.notices.clone())?;
        Ok(Box::new(bridge))
    }

    /// Never reached: [`HostPlan::new`] refuses `--hosts` above 1 without the feature.
    #[cfg(not(feature = "hosts"))]
    fn listen(
        &self,
        _endpoint: &str,
        _s: &Scenario,
        _team: &TeamName,
        _flight: TeamFlight,
    ) -> Result<Box<dyn OtherHosts>, BridgeError> {
        Ok(Box::new(OneHost))
    }
}

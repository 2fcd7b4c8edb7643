//! The HTTP layer's own rules tested without a server: hosts, tokens,
//! origins, connection slots.

use super::*;

fn address(last: u8) -> IpAddr {
    IpAddr::from([127, 0, 0, last])
}

/// One address takes up to its cap; the reserved slots go only to
/// addresses holding a few; a given-back slot is taken again.
#[test]
fn the_reserved_slots_go_to_addresses_holding_few() {
    let slots = Arc::new(Slots::new(HttpLimits {
        max_connections: 20,
        max_connections_per_address: 12,
        reserved_connections: 4,
        ..HttpLimits::default()
    }));
    let mut flood: Vec<Slot> = (0..12).map_while(|_| slots.take(address(1))).collect();
    assert_eq!(flood.len(), 12, "one address up to its cap");
    assert!(slots.take(address(1)).is_none());
    // A second address takes the 4 open slots left, then reserved ones
    // while it holds fewer than FEW_CONNECTIONS (8).
    let second: Vec<Slot> = (0..12).map_while(|_| slots.take(address(2))).collect();
    assert_eq!(second.len(), 8);
    // All 20 taken: nobody else, not even a newcomer.
    assert!(slots.take(address(3)).is_none());
    flood.truncate(10);
    let newcomer = slots
        .take(address(3))
        .expect("a reserved slot for a newcomer");
    assert!(
        slots.take(address(2)).is_none(),
        "not for an address holding many"
    );
    // The IPv4-mapped form of an address counts as the address.
    let mapped = IpAddr::from(std::net::Ipv4Addr::new(127, 0, 0, 3).to_ipv6_mapped());
    let again = slots.take(mapped).expect("the last reserved slot");
    assert_eq!(again.address, newcomer.address);
    drop((flood, second, newcomer, again));
    let held = slots.held.lock().unwrap();
    assert_eq!((held.total, held.per_address.len()), (0, 0));
}

#[test]
fn only_this_servers_own_pages_are_same_origin() {
    let headers = |pairs: &[(&'static str, &'static str)]| {
        let mut map = HeaderMap::new();
        for (name, value) in pairs {
            map.insert(*name, HeaderValue::from_static(value));
        }
        map
    };
    let host = ("host", "127.0.0.1:7879");
    for own in [
        vec![host],
        vec![host, ("origin", "http://127.0.0.1:7879")],
        vec![("host", "Dash.Example"), ("origin", "https://dash.example")],
        vec![host, ("sec-fetch-site", "same-origin")],
        vec![host, ("sec-fetch-site", "none")],
    ] {
        assert_eq!(cross_origin(&headers(&own)), None, "{own:?}");
    }
    for other in [
        vec![host, ("sec-fetch-site", "cross-site")],
        vec![host, ("sec-fetch-site", "same-site")],
        vec![host, ("origin", "http://127.0.0.1:7880")],
        vec![host, ("origin", "http://localhost:7879")],
        vec![host, ("origin", "null")],
        vec![host, ("origin", "ftp://127.0.0.1:7879")],
        vec![("origin", "http://127.0.0.1:7879")],
        vec![
            host,
            ("origin", "http://127.0.0.1:7879"),
            ("sec-fetch-site", "same-site"),
        ],
    ] {
        assert!(cross_origin(&headers(&other)).is_some(), "{other:?}");
    }
}

"""A board link and an axis control loop log on behalf of their node (sslfr_common.log_route)."""
from sslfr_common.log_route import NODE_ATTR


def test_board_link_and_control_loop_carry_their_owner():
    from sslfr_drivers.axis.control_loop import ControlLoop
    from sslfr_drivers.link.board_link import BoardLink
    from sslfr_drivers.link.transport import make_transport
    link = BoardLink(make_transport('/dev/null-sslfr-test'), owner='absorber_board')
    assert link.log_extra == {NODE_ATTR: 'absorber_board'} and link._reader._extra == link.log_extra
    assert ControlLoop(lambda: 1.0, owner='mirrors_driver')._extra == {NODE_ATTR: 'mirrors_driver'}

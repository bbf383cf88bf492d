"""plot_bag on damaged bags and bad paths: what came before is plotted, errors in one line."""

import sys

from bag.helpers import make_bag, one_line
from bag.test_reader import corrupt_bag

from tskf_ros.bag.reader import EXIT_DAMAGED
from tskf_ros.tools import plot_bag

import yaml


def test_plot_bag_on_a_truncated_bag_plots_what_came_before(tmp_path, capsys):
    bag = make_bag(tmp_path / 'bag', range(60), chunk_size=2000)
    mcap = bag / 'bag.mcap'
    data = mcap.read_bytes()
    mcap.write_bytes(data[:len(data) * 6 // 10])
    code = plot_bag.main([str(bag), '--out', str(tmp_path / 'png')])
    err = capsys.readouterr().err
    assert code == EXIT_DAMAGED
    one_line(err, 'plot_bag: bag damaged; plotted what came before: ', str(mcap),
             'truncated')
    assert (tmp_path / 'png' / 'estimator.png').is_file()


def test_plot_bag_when_nothing_before_the_damage_writes_nothing(tmp_path, capsys):
    bag = make_bag(tmp_path / 'bag', range(10))
    mcap = bag / 'bag.mcap'
    mcap.write_bytes(mcap.read_bytes()[:40])
    code = plot_bag.main([str(bag), '--out', str(tmp_path / 'png')])
    err = capsys.readouterr().err
    assert code == EXIT_DAMAGED
    one_line(err, 'plot_bag: bag damaged, nothing before the damage to plot: ', str(mcap),
             'the 0 message(s) before it')
    assert not (tmp_path / 'png').exists()


def test_plot_bag_refuses_a_missing_path(tmp_path, capsys):
    assert plot_bag.main([str(tmp_path / 'nope')]) == 1
    one_line(capsys.readouterr().err, 'plot_bag: error: ', 'no such bag')
    assert list(tmp_path.iterdir()) == []


def test_plot_bag_on_a_flipped_bit_reports_the_crc_damage(tmp_path, capsys):
    bag = corrupt_bag(tmp_path / 'bag')
    assert plot_bag.main([str(bag), '--out', str(tmp_path / 'png')]) == EXIT_DAMAGED
    assert 'chunk CRC mismatch' in capsys.readouterr().err


def test_a_bag_of_an_unknown_package_type_is_refused_in_one_line(tmp_path, capsys):
    bag = make_bag(tmp_path / 'bag', range(5))
    meta = bag / 'metadata.yaml'
    doc = yaml.safe_load(meta.read_text())
    doc['rosbag2_bagfile_information']['topics_with_message_count'][0]['topic_metadata'][
        'type'] = 'this/msg/X'
    meta.write_text(yaml.safe_dump(doc))
    assert plot_bag.main([str(bag), '--out', str(tmp_path / 'png')]) == 1
    out = capsys.readouterr()
    assert 'Zen' not in out.out
    one_line(out.err, 'plot_bag: error: ', 'this/msg/X')
    assert 'this' not in sys.modules

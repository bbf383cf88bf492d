# Copyright 2026 The tskf_ros authors
# SPDX-License-Identifier: Apache-2.0
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""metadata.yaml of a bag as rosbag2 (Jazzy, metadata version 9) writes it, written durably."""

import os
from pathlib import Path
from typing import Optional, Sequence

from rosbags.rosbag2.metadata import dump_qos_v9

from tskf_ros.bag.mcap_file import McapStats, scan_mcap

import yaml

__all__ = ['add_custom_data', 'file_metadata', 'merge_metadata', 'METADATA_MARKER',
           'METADATA_VERSION', 'write_metadata', 'write_yaml']

# custom_data key (and value) of every bag this package writes; overwrite needs it
METADATA_MARKER = ('tskf_ros.writer', 'tskf_ros')
# metadata.yaml version (rosbag2 Jazzy)
METADATA_VERSION = 9


def write_yaml(path: Path, doc: dict) -> None:
    """Write a YAML document durably: a temporary file, fsync, rename."""
    tmp = path.parent / f'.{path.name}.tmp'
    with tmp.open('w') as f:
        yaml.safe_dump(doc, f, default_flow_style=False, sort_keys=False)
        f.flush()
        os.fsync(f.fileno())
    tmp.replace(path)


def write_metadata(bagdir: Path, path: Path, *, stats: Optional[McapStats] = None,
                   custom_data: Optional[dict] = None) -> dict:
    """
    Write bagdir/metadata.yaml (rosbag2 version 9) for the MCAP file `path`; return it.

    stats: the file's topics, counts and log time span; read from the file if None.
    """
    info = file_metadata(path, stats=stats, custom_data=custom_data)
    write_yaml(bagdir / 'metadata.yaml', {'rosbag2_bagfile_information': info})
    return info


def file_metadata(path: Path, *, stats: Optional[McapStats] = None,
                  custom_data: Optional[dict] = None) -> dict:
    """Return the metadata (rosbag2_bagfile_information) of a bag of the one MCAP file."""
    stats = stats or scan_mcap(path)
    counts, lo, hi = stats.counts, stats.first, stats.last
    total = sum(counts.values())
    span = {'nanoseconds': (hi - lo) if total else 0}
    start = {'nanoseconds_since_epoch': lo or 0}
    data = dict(custom_data or {})
    data[METADATA_MARKER[0]] = METADATA_MARKER[1]
    info = {
        'version': METADATA_VERSION,
        'storage_identifier': 'mcap',
        'relative_file_paths': [path.name],
        'duration': span,
        'starting_time': start,
        'message_count': total,
        'topics_with_message_count': [
            {'topic_metadata': {'name': name, 'type': ti.msgtype,
                                'serialization_format': ti.serialization_format or 'cdr',
                                'offered_qos_profiles': dump_qos_v9(ti.qos),
                                'type_description_hash': digest},
             'message_count': counts.get(name, 0)}
            for name, (ti, digest) in stats.topics.items()],
        'compression_format': '',
        'compression_mode': '',
        'files': [{'path': path.name, 'starting_time': dict(start), 'duration': dict(span),
                   'message_count': total}],
        'custom_data': data,
        'ros_distro': 'jazzy',
    }
    return info


def merge_metadata(infos: Sequence[dict], custom_data: Optional[dict] = None) -> dict:
    """Merge the metadata of consecutive files of one bag into the bag's metadata."""
    info = dict(infos[0])
    info['relative_file_paths'] = [p for i in infos for p in i['relative_file_paths']]
    files = [f for i in infos for f in i['files']]
    info['files'] = files
    topics: dict = {}
    for i in infos:
        for entry in i['topics_with_message_count']:
            name = entry['topic_metadata']['name']
            if name in topics:
                topics[name]['message_count'] += entry['message_count']
            else:
                topics[name] = {'topic_metadata': entry['topic_metadata'],
                                'message_count': entry['message_count']}
    info['topics_with_message_count'] = list(topics.values())
    info['message_count'] = sum(i['message_count'] for i in infos)
    spans = [(f['starting_time']['nanoseconds_since_epoch'],
              f['starting_time']['nanoseconds_since_epoch'] + f['duration']['nanoseconds'])
             for f in files if f['message_count']]
    start = min((s for s, _ in spans), default=0)
    info['starting_time'] = {'nanoseconds_since_epoch': start}
    info['duration'] = {'nanoseconds': max((e for _, e in spans), default=start) - start}
    data: dict = {}
    for i in infos:
        data.update(i.get('custom_data') or {})
    data.update(custom_data or {})
    data[METADATA_MARKER[0]] = METADATA_MARKER[1]
    info['custom_data'] = data
    return info


def add_custom_data(bagdir: Path, custom_data: dict) -> None:
    """Add custom_data entries and METADATA_MARKER to a metadata.yaml another writer wrote."""
    meta = bagdir / 'metadata.yaml'
    doc = yaml.safe_load(meta.read_text())
    info = doc['rosbag2_bagfile_information']
    data = dict(info.get('custom_data') or {})
    data.update(custom_data)
    data[METADATA_MARKER[0]] = METADATA_MARKER[1]
    info['custom_data'] = data
    write_yaml(meta, doc)
